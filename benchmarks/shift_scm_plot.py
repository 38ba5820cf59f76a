"""Plots the compass W against the true heading in each regime of both deployment shifts.

For every (shift, strength, regime) panel it draws headings uniformly, the gust of one
window from that regime's gust process, and W from that env's own sensor (the env's
``gusts``, ``sensor`` and ``compass_rotation``, so the plot shows what the envs compute),
and scatters W's angle against the heading's: calm steps in grey, steps with a gust coloured
by the gust's direction. ``docs/shift_scm.png`` is its output:

    OMP_NUM_THREADS=1 python benchmarks/shift_scm_plot.py --out docs/shift_scm.png
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import torch  # noqa: E402

from torchrl_causal.cli.arguments import OneLineParser, count, non_negative  # noqa: E402
from torchrl_causal.envs import RoverMazeEnv  # noqa: E402
from torchrl_causal.envs.base import REGIMES, GustProcess  # noqa: E402

#: (row title, shift, strength)
PANELS: tuple[tuple[str, str, float], ...] = (
    ("rotation (default), strength 1", "rotation", 1.0),
    ("prior, strength 1", "prior", 1.0),
    ("prior, strength 0.5", "prior", 0.5),
    ("prior, strength 0", "prior", 0.0),
)


def sample(shift: str, strength: float, regime: str, samples: int, seed: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(heading angle, W angle, gust)`` of ``samples`` independent steps of that regime."""
    env = RoverMazeEnv("u", batch_size=1, regime=regime, confounding_strength=strength, shift=shift, seed=seed)
    generator = torch.Generator().manual_seed(seed)
    heading = (2 * torch.rand(samples, generator=generator) - 1) * math.pi
    signal = torch.stack((heading.cos(), heading.sin()), dim=-1)
    gust = env.gusts.draw((samples,), generator=generator)
    w = env.sensor.read(signal, gust, rotation=env.compass_rotation, generator=generator)
    env.close()
    return heading, torch.atan2(w[:, 1], w[:, 0]), gust


def plot(out: Path, samples: int, seed: int) -> None:
    figure, axes = plt.subplots(len(PANELS), len(REGIMES), figsize=(6.0, 2.2 * len(PANELS)), sharex=True, sharey=True)
    for row, (title, shift, strength) in enumerate(PANELS):
        for column, regime in enumerate(REGIMES):
            heading, w_angle, gust = sample(shift, strength, regime, samples, seed)
            blowing = gust.norm(dim=-1) > 0
            direction = GustProcess.direction(gust[blowing])
            ax = axes[row, column]
            ax.scatter(heading[~blowing], w_angle[~blowing], s=1, c="0.7", rasterized=True)
            ax.scatter(
                heading[blowing],
                w_angle[blowing],
                s=2,
                c=torch.atan2(direction[:, 1], direction[:, 0]),
                cmap="twilight",
                vmin=-math.pi,
                vmax=math.pi,
                rasterized=True,
            )
            share = float(blowing.float().mean())
            ax.set_title(f"{title}\n{regime} (gusts in {100 * share:.0f}% of steps)", fontsize=7)
            ax.set_xlim(-math.pi, math.pi)
            ax.set_ylim(-math.pi, math.pi)
            ax.tick_params(labelsize=6)
            if row == len(PANELS) - 1:
                ax.set_xlabel("heading (rad)", fontsize=7)
            if column == 0:
                ax.set_ylabel("angle of W (rad)", fontsize=7)
    figure.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=72)
    plt.close(figure)


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/shift_scm.png"))
    parser.add_argument("--samples", type=count, default=1200, help="steps per panel")
    parser.add_argument("--seed", type=non_negative, default=0)
    args = parser.parse_args()
    torch.set_num_threads(1)
    plot(args.out, args.samples, args.seed)
    print(f"wrote {args.out} ({args.out.stat().st_size / 1024:.0f} kB)")


if __name__ == "__main__":
    main()
