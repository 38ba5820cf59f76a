"""CPU time of one Causal BC training epoch: the paper's 256 x 4 actor against scale=cpu_ant's 128 x 2.

Builds each actor with :func:`~torchrl_causal.modules.make_deterministic_actor` and
:class:`~torchrl_causal.objectives.HuberBCLoss` as ``algo=bc`` does, and runs ``--epochs``
epochs of Adam on shuffled minibatches of 2048 over ``--rows`` synthetic rows of the AntMaze
window's width (355 features, 8 action dims), plus the validation pass over a quarter as many.
Each epoch is timed by this process's CPU time (``time.process_time``, which the other jobs of a
shared machine do not inflate), and the ratio of the two actors is printed. No env, no
demonstrations: the update cost depends only on the row count, widths and batch size.

Row counts of the 200-demonstration sets (80% of the transitions):
AntMaze-Medium ~61k (174 successful episodes of ~288 steps and 26 of 1000), AntMaze-Large
~94k (158 of ~475 and 42 of 1000); 1000 demonstrations are 5 times as many.

Usage:
    OMP_NUM_THREADS=1 python benchmarks/bc_epoch_cost.py [--rows 61000] [--epochs 2]
"""

from __future__ import annotations

import time

import torch
from tensordict import TensorDict
from torchrl.data import Bounded

from torchrl_causal.cli.arguments import OneLineParser, count
from torchrl_causal.experiment.provenance import cpu_model
from torchrl_causal.modules import make_deterministic_actor
from torchrl_causal.objectives import HuberBCLoss

OBSERVATION, ACTION, BATCH = 355, 8, 2048
ACTORS = {"cpu_ant 128 x 2": (128, 2), "paper 256 x 4": (256, 4)}


def epoch_seconds(hidden: int, num_blocks: int, rows: int, epochs: int) -> float:
    """Mean CPU seconds of one epoch (updates and validation) of the actor ``hidden x num_blocks``."""
    generator = torch.Generator().manual_seed(0)
    spec = Bounded(-1.0, 1.0, shape=(ACTION,))
    loss = HuberBCLoss(make_deterministic_actor(OBSERVATION, spec, hidden=hidden, num_blocks=num_blocks))
    optimizer = torch.optim.Adam(loss.parameters(), lr=3e-4)
    data = TensorDict({"observation": torch.randn(rows, OBSERVATION, generator=generator), "action": spec.rand((rows,))}, [rows])
    val = data[: rows // 4]
    start = time.process_time()
    for _ in range(epochs):
        order = torch.randperm(rows, generator=generator)
        for first in range(0, rows, BATCH):
            value = loss(data[order[first : first + BATCH]])["loss_bc"]
            optimizer.zero_grad(set_to_none=True)
            value.backward()
            optimizer.step()
        with torch.no_grad():
            for first in range(0, val.numel(), BATCH):
                loss(val[first : first + BATCH])
    return (time.process_time() - start) / epochs


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=count, default=61000, help="training rows (80%% of the demonstrations' transitions)")
    parser.add_argument("--epochs", type=count, default=2)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"CPU {cpu_model()}, torch {torch.__version__}, 1 thread, {args.rows} rows, batch {BATCH}, {args.epochs} epochs each")
    seconds = {name: epoch_seconds(*shape, args.rows, args.epochs) for name, shape in ACTORS.items()}
    for name, value in seconds.items():
        print(f"| {name} | {value:.2f} CPU s / epoch |")
    print(f"ratio paper / cpu_ant: {seconds['paper 256 x 4'] / seconds['cpu_ant 128 x 2']:.2f}")


if __name__ == "__main__":
    main()
