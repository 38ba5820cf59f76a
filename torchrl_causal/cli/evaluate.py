"""Evaluate a finished run: ``python -m torchrl_causal.evaluate run_dir=<dir> regime=deploy episodes=1000``.

Over :func:`torchrl_causal.lifecycle.evaluate_run`: rebuilds the run's policy from its saved config and adjustment window, loads
``checkpoints/best.pt`` (the expert is rebuilt from the env) and runs ``episodes``
episodes in batches of ``num_envs`` (default: the run's ``eval.num_envs``), seeded with
``seed``. ``confounding_strength=<s>`` evaluates under another deployment shift,
``trajectories=<n>`` keeps the positions of ``n`` episodes. Prints the success rate ±
SE, raw E[Y] ± std and the length of successful episodes, and (unless ``save=false``)
writes the record to ``<run_dir>/eval/<regime>-<settings>.json``, named after every
setting that changes the numbers: the final evaluation of training
(``eval/<regime>.json``, what the report reads) is never replaced. A run directory that is not
ours to write into (a shipped policy in ``results/policies/``, a read-only or shared folder) is
only read: its record goes to ``<run_root>/evaluated/...`` (``run_root=runs`` by default), and
the command prints where.
``device=<cpu|cuda|...>`` picks where the policy runs; by default the run's own device
when this machine has it, else the CPU (a run trained on a GPU evaluates anywhere).
``video=<n>`` records the first ``n`` episodes as videos (the ``[video]`` extra), to
``logs/videos/<regime>-<settings>/episode_<i>.mp4`` beside where the record goes (so below
``run_root`` for a shipped policy); ``video_format=gif`` and ``video_every=<k>`` (a frame
every ``k`` steps) default to the run's ``eval.video_format`` and ``eval.video_every``. The
record is the same with or without videos.
The expert row walks the skill body its ``config.yaml`` records (``env.expert_body``: the
weights file and its digest), refused when that file is gone or holds another body; a run
made before runs recorded it is refused unless ``expert_weights=<name or file>`` says which
body it walked (an expert without a weights file, RoverMaze's, needs none).
``threads=<n>`` (default 1, as training's ``threads``) sets ``torch.set_num_threads``. Torch's
own default, a thread per core, oversubscribes a small machine that runs anything else: on
2 cores with two evaluations at once, 1000 RoverMaze episodes of a C-IQ-Learn policy took
325 s with it and 15 s with one thread each.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from torchrl_causal.cli.arguments import Option, argv_or_sys, one_line_errors, parse_arguments
from torchrl_causal.errors import MissingDependencyError, RenderingUnavailable
from torchrl_causal.evaluation.metrics import EvaluationResult
from torchrl_causal.evaluation.video import VIDEO_FORMATS
from torchrl_causal.experiment.run_directory import CheckpointError
from torchrl_causal.lifecycle import DEFAULT_THREADS, REGIMES, evaluate_run, evaluation_record, evaluation_videos

__all__ = ["OPTIONS", "main"]

OPTIONS: dict[str, Option] = {
    "run_dir": Option(str, placeholder="<dir>", help="the run directory (holding config.yaml and checkpoints/best.pt)"),
    "regime": Option(str, "deploy", choices=REGIMES, help="the regime to evaluate in"),
    "episodes": Option(int, 1000, ge=1, help="episodes to run"),
    "num_envs": Option(int, None, ge=1, placeholder="<the run's eval.num_envs>", help="episodes run at once"),
    "seed": Option(int, 30_000, ge=0, help="the evaluation seed"),
    "confounding_strength": Option(float, None, ge=0.0, le=1.0, placeholder="<the run's>", help="the deployment shift"),
    "trajectories": Option(int, 0, ge=0, help="episodes whose positions are kept"),
    "save": Option(bool, True, help="write the record to <run_dir>/eval/ (below run_root for a run not ours to write into)"),
    "reuse": Option(bool, False, help="read back a record of the same settings instead of evaluating"),
    "device": Option(str, None, placeholder="<the run's, else cpu>", help="where the policy runs"),
    "threads": Option(int, DEFAULT_THREADS, ge=1, help="torch threads"),
    "run_root": Option(str, "runs", help="a run not ours to write into gets its record in <run_root>/evaluated/"),
    "video": Option(int, 0, ge=0, help="record the first N episodes as videos in logs/videos/<regime>-<settings>/ beside the record"),
    "video_format": Option(str, None, choices=VIDEO_FORMATS, placeholder="<the run's eval.video_format>", help="mp4 or gif"),
    "video_every": Option(int, None, ge=1, placeholder="<the run's eval.video_every>", help="a video frame every this many steps"),
    "expert_weights": Option(
        str,
        None,
        placeholder="<the body the run records>",
        help="the expert row's skill body (a shipped body's name, e.g. steady, or a weights file), for a run that records none",
    ),
}
EXAMPLE = "python -m torchrl_causal.evaluate run_dir=runs/rovermaze_u/h1000-cs1.0-k10/c_bc/seed0 regime=deploy episodes=200"


def _pm(mean: float, spread: float, digits: int = 1) -> str:
    """``mean ± spread``, or ``—`` for a mean of no values (no episode succeeded)."""
    if math.isnan(mean):
        return "—"
    return f"{mean:.{digits}f}" + ("" if math.isnan(spread) else f" ± {spread:.{digits}f}")


def main(argv: Sequence[str] | None = None) -> EvaluationResult:
    args = parse_arguments("evaluate", argv_or_sys(argv), OPTIONS, about=__doc__, example=EXAMPLE)
    torch.set_num_threads(args.pop("threads"))
    with one_line_errors(CheckpointError, MissingDependencyError, RenderingUnavailable):
        result = evaluate_run(**args)
        settings = {key: args[key] for key in ("num_envs", "seed", "confounding_strength", "run_root")}
        record = evaluation_record(args["run_dir"], args["regime"], args["episodes"], **settings)
        videos = evaluation_videos(args["run_dir"], args["regime"], args["episodes"], **settings) if args["video"] else None
    print(
        f"{args['run_dir']} [{result.regime}] episodes {result.n_episodes}: success {100 * result.success_rate:.1f}% "
        f"± {100 * result.success_se:.1f}, E[Y] {result.return_mean:.1f} ± {result.return_std:.1f}, "
        f"successful episode length {_pm(result.ep_len_mean, result.ep_len_std, 0)}"
    )
    if args["save"] and record.is_file():
        print(f"record: {record}")
    if videos is not None:
        print(f"videos: {videos} ({min(args['video'], result.n_episodes)} episodes)")
    return result


if __name__ == "__main__":
    main()
