"""Hand-built `TrialData` for the baselines' tests: known EP lengths, channels and signals."""

from __future__ import annotations

import numpy as np

from tactile_exp.data.layout import BASELINE_STATE, EPS, FingerData, TrialData, TrialName

GAP = b"OPEN_GRIPPER_BY_2CM_FAST"


def make_trial(
    name: str = "foam_101_01",
    lengths: tuple[int, int, int, int] = (120, 200, 100, 60),
    seed: int = 0,
    gripper: bool = True,
    translation: bool = True,
    offset: float = 0.0,
) -> TrialData:
    """A trial with 30 rest rows, the 4 EPs of ``lengths`` rows, random ADC-like signals.

    ``offset`` shifts every BioTac channel, which the static features must not see.
    """
    rng = np.random.default_rng(seed)
    states = [b"DISABLED"] * 5 + [BASELINE_STATE] * 30
    for state, n in zip(EPS.values(), lengths, strict=True):
        states += [state] * n + [GAP] * 5
    detail = np.array(states, dtype="S30")
    n = len(detail)

    def channel(*shape: int) -> np.ndarray:
        return (rng.integers(1500, 2500, (n, *shape)) + offset).astype(np.int64)

    fingers = tuple(
        FingerData(
            electrodes=channel(19),
            pac=channel(22).reshape(-1),
            pdc=channel(),
            tac=channel(),
            tdc=channel(),
        )
        for _ in range(2)
    )
    trial = TrialData(TrialName.parse(name), fingers, detail)  # type: ignore[arg-type]
    if gripper:
        trial.gripper = {"joint_position": rng.random(n)}
    if translation:
        trial.translation = rng.random((n, 3))
    return trial
