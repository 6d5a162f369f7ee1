"""Many runs at once: ``dynslam2d batch`` and the engine ``dynslam2d experiment`` shares.

- :mod:`dynslam2d.batch.jobs`: the (input, setting) jobs, their order and folder names;
- :mod:`dynslam2d.batch.engine`: run jobs serially, on a process pool or on Ray, outcomes in order;
- :mod:`dynslam2d.batch.runs`: one results folder per job, resume, batch.csv / batch.md / batch.json.

How inputs and results travel between the driver and the workers: docs/batch.md.
"""

from dynslam2d.batch.engine import RAY_HINT, Outcome, map_jobs
from dynslam2d.batch.jobs import Job, Setting, make_jobs, parse_setting
from dynslam2d.batch.runs import BatchResult, run_batch

__all__ = ["BatchResult", "Job", "Outcome", "RAY_HINT", "Setting", "make_jobs", "map_jobs", "parse_setting",
           "run_batch"]
