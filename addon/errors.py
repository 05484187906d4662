"""The add-on's errors: what a user is told, raised anywhere in the add-on."""


class DeformKitError(Exception):
    """A setup problem or a native failure, with a message for the user."""


class OverlapError(DeformKitError):
    """Two of a deformer's vertex groups share vertices that may belong to one only. The
    panel offers Select Shared and Remove from <group> (operators.DEFORMKIT_OT_overlap)."""

    def __init__(self, msg, group_a, group_b):
        super().__init__(msg)
        self.groups = (group_a, group_b)
