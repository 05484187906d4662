"""A bind's progress as the status bar shows it ("factorizing 62%"), reported by the native
bind from its worker thread."""


# What the status bar calls the native binds' phases (deformkit.BindProgress.phase).
BIND_PHASES = {
    "renumber": "renumbering", "cells": "building cells", "operator": "building the operator",
    "constraints": "reading constraints", "system": "building the system",
    "assemble": "assembling", "analyze": "analysing", "factorize": "factorizing",
    "basis": "handle basis", "heat": "heat method", "distances": "distances",
    "nodes": "placing nodes", "weights": "node weights", "edges": "graph edges",
    "eigenvectors": "eigenvectors", "forms": "fundamental forms", "regions": "regions",
    "skeletons": "skeletons", "coarse": "simplifying (coarse level)",
    "tetrahedralize": "filling with tetrahedra", "interior": "interior", "arap": "binding ARAP",
    "done": "finishing",
}


class Reporting:
    """What a bind job reports: `fraction` and `phase` written by the native progress callback
    (_progress, in the worker thread), read by the main thread (progress_text); setting
    `cancelled` asks the native bind to stop."""
    fraction, phase, cancelled = None, None, False

    def _progress(self, fraction):
        # the phase first: the main thread reads fraction, then phase (progress_text)
        self.phase = getattr(fraction, "phase", None)
        self.fraction = float(fraction)
        return self.cancelled

    def progress_text(self):
        """The bind's phase and fraction for the status bar ("factorizing 62%"), "" before
        the first report or for a method without bind progress."""
        frac = self.fraction
        if frac is None:
            return ""
        phase = self.phase
        return "%s %.0f%%" % (BIND_PHASES.get(phase, phase or "bind"), 100 * frac)
