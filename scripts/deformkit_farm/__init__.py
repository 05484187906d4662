"""scripts/farm_bake.py's parts: the chunk plan (plan.py), one chunk in a headless Blender
(chunk.py), the chunks as Dask tasks (dask_bake.py), and the job files for other farms
(openjd.py, flamenco.py, slurm.py), all from the same plan."""
