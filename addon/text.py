"""Wording of the add-on's user-facing texts: counts with the right plural, nouns with the right
article. Pure Python (no bpy), so that every module can use it."""

# words whose plural is not the word + "s"
_PLURALS = {"vertex": "vertices"}


def plural(n, word, many=None):
    """'1 handle', '2 handles', '0 handles'; '1 vertex', '3 vertices' (`many` overrides the
    plural form)."""
    if n == 1:
        return "%d %s" % (n, word)
    return "%d %s" % (n, many or _PLURALS.get(word, word + "s"))


def article(word):
    """'a mesh', 'an empty', 'an armature': the word with its indefinite article (by its
    first letter; the add-on's words have no silent 'h' or 'eu-' sounds)."""
    return ("an " if word[:1].lower() in ("a", "e", "i", "o", "u") else "a ") + word
