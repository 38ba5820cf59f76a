"""How AntMaze episodes fail: kept as the name earlier results quote; ``benchmarks/maze_failures.py``
classifies AntMaze and HumanoidMaze episodes alike (a flipped ant is its "down" class).

    OMP_NUM_THREADS=1 python benchmarks/antmaze_failures.py RUN_DIR [RUN_DIR ...] --regime deploy --episodes 200
"""

from __future__ import annotations

import runpy
from pathlib import Path

if __name__ == "__main__":
    runpy.run_path(str(Path(__file__).with_name("maze_failures.py")), run_name="__main__")
