"""Time-slice causal templates of the authors' environment suite (pure data, no torch).

Each confounded env exposes its template as ``env.causal_template``. Lags count steps
back: ``(src, dst, lag)`` means ``src`` at ``t - lag`` -> ``dst`` at ``t``. The latent
wind appears as the bidirected edges (``W <-> L`` / ``W <-> C`` within a slice, and both
ends with the reward).
"""

from __future__ import annotations

from torchrl_causal.graphs.template import TimeSliceTemplate

__all__ = ["ANTMAZE_TEMPLATE", "HUMANOIDMAZE_TEMPLATE"]


def _persistence(variables: str) -> list[tuple[str, str, int]]:
    return [(v, v, 1) for v in variables]


#: Confounded AntMaze — P position, O orientation (hidden from the imitator), A joint
#: angles, L torso linear velocity, T torso angular velocity, J joint velocities,
#: W compass, X torques.
ANTMAZE_TEMPLATE = TimeSliceTemplate(
    variables=("P", "O", "A", "L", "T", "J", "W", "X"),
    action="X",
    observed=("P", "A", "L", "T", "J", "W", "X"),
    directed=(
        ("J", "A", 0),
        ("J", "T", 0),
        ("J", "L", 0),
        ("T", "O", 0),
        ("A", "O", 0),
        ("A", "L", 0),
        ("O", "L", 0),
        ("L", "P", 0),
        ("O", "W", 0),
        *[(v, "X", 0) for v in "PLTOJA"],
        ("X", "J", 1),
        *_persistence("POALTJX"),
    ),
    bidirected=(("W", "L", 0),),
    reward_parents=("P",),
    reward_bidirected=("W", "L"),
    reward_slices="all",
)

#: Confounded HumanoidMaze — P position, A joint angles, H head height, E extremities,
#: V torso vertical, C centre-of-mass velocity (hidden from the imitator), J joint
#: velocities, W ground vibration, X torques.
HUMANOIDMAZE_TEMPLATE = TimeSliceTemplate(
    variables=("P", "A", "H", "E", "V", "C", "J", "W", "X"),
    action="X",
    observed=("P", "A", "H", "E", "V", "J", "W", "X"),
    directed=(
        ("J", "A", 0),
        ("J", "C", 0),
        ("A", "V", 0),
        ("A", "E", 0),
        ("A", "H", 0),
        ("C", "P", 0),
        ("V", "C", 0),
        ("H", "P", 0),
        ("E", "P", 0),
        ("C", "W", 0),
        *[(v, "X", 0) for v in "PAHEVCJ"],
        ("X", "J", 1),
        *_persistence("PAHEVCJX"),
    ),
    bidirected=(("W", "C", 0),),
    reward_parents=("P",),
    reward_bidirected=("W", "C"),
    reward_slices="all",
)
