"""Bridges Blender data and the native solvers; no numerics here.

Blender -> arrays: vertex groups become index arrays (and weight arrays), handle targets become
4x4 transforms in the deformed object's space, exactly like a Hook modifier:
    T = inverse(object world) @ target world @ bind_matrix,
    bind_matrix = inverse(target world at bind) @ object world at bind.
Arrays -> Blender: offset = solved - rest is written into the deformer's point attribute, read by
its Geometry Nodes modifier. The base mesh positions are never written.

Solver state (native objects) is cached by (object name, deformer uid) and holds no bpy
references; it is rebuilt on demand (after file load, undo, settings or group changes).

One idea per module: cache (what is kept between updates), calls (the native module's
errors), blender_data (reading the mesh, writing the result), controls (the collector for
the control kinds a method declares), vertex_groups (the collector for vertex-group
controls), identity (topology and deformer uids), binding, rebind (re-binds
in worker threads), solving, budget (interactive time budgets), workers (solves off the main
thread), previews, status (what the panel says), material (linear reconstruction's map),
simulation (a dynamic method's frames, played from the scene's start, and checkpoints).
The names below are what the rest of the add-on uses; tests that tune or spy on a module
reach into it (solver.budget.INTERACTIVE_BUDGET_MS).
"""

from ..errors import DeformKitError, OverlapError  # noqa: F401
from . import (binding, blender_data, budget, cache, calls, controls, identity,  # noqa: F401
               material, previews, progress, rebind, simulation, solving, status,
               vertex_groups, workers)
from .binding import (BindJob, bind, bind_begin, bind_end,  # noqa: F401
                      bind_warnings, rest_frame, unbind)
from .blender_data import (check_editable, check_mesh_type, evaluated_positions,  # noqa: F401
                           rest_positions, triangles)
from .budget import inner_cap  # noqa: F401
from .cache import (clear_cache, converges_next, drop, drop_pending, mark_all_dirty,  # noqa: F401
                    mark_settings_changed, mark_unverified, pending, previewing, refining,
                    running_binds, runtime, settling, working)
from .identity import (check_single_user, check_topology, ensure_own_uid,  # noqa: F401
                       new_uid, quick_topology, topology_fingerprint)
from .material import material_map  # noqa: F401
from .progress import BIND_PHASES  # noqa: F401
from .rebind import (REBIND_ASYNC_MIN_VERTICES, GroupsRebindJob, RebindPending,  # noqa: F401
                     finish_rebinds, rebind_text, rebinding, threaded_rebinds)
from .solving import (binding_of, deformed_positions, evaluate_object, finish,  # noqa: F401
                      frame_key, shown_positions, solve)
from .status import (fit_warning, idle_status, reset_status, set_status,  # noqa: F401
                     simulation_text, solve_summary, status_text)
from .workers import FrameSolve, threaded_solves  # noqa: F401
