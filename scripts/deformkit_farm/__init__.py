"""scripts/farm_bake.py's parts: the chunk plan (plan.py), one chunk in a headless Blender
(chunk.py), the chunks as Dask tasks (dask_bake.py), the job files for other farms
(jobfiles.py, with the Flamenco job type deformkit_bake.js), all from the same plan, and a
loopback cluster of separate processes for the tests and the benchmark (loopback.py)."""
