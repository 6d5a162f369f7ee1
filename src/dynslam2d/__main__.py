"""``python -m dynslam2d`` = the ``dynslam2d`` command."""

from dynslam2d.cli import main

main()
