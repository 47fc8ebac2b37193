"""The rules of the claims table (results/claims.md): statuses, the seed data a claim reads,
the seed-spread and standing-still rules, the data's reference row and the Markdown.

pimann.evaluate.claims checks each of the paper's claims with these; the rules are printed in the
table's header (`RULES`). Neither "holds within seed spread" nor "holds (model stands still)"
counts as holding.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import pandas as pd

from pimann.evaluate.data_reference import reference_value
from pimann.evaluate.metrics import WALK_TOUCHDOWNS
from pimann.generate.rollout_layout import BASELINE, pi_models, select_rows, weight_label

HOLDS, FAILS, NOT_COMPARABLE = "holds", "does not hold", "not comparable"
WITHIN_SPREAD, STANDS_STILL = "holds within seed spread", "holds (model stands still)"
REFERENCE = "reference"
C1_FACTOR = 2.0  # C1 holds within this factor of the paper's numbers, both ways
RMSE_FIGURE = "pi_weight_comparison"
VELOCITY = "velocity-level sliding RMSE (the authors')"
POSITION = "position-level sliding RMSE"
RULES = [
    "**holds**: the claimed order holds with the seed ranges separated, for every pair of "
    "conditions the claim compares: the worse condition's best seed is still worse than the "
    "better condition's worst seed.",
    f"**{WITHIN_SPREAD}**: only the seed medians order as claimed (not counted as holding).",
    f"**{STANDS_STILL}**: it would hold, but some seed of a model the claim favours (the one "
    "said to slide, drift or move less) does not walk: forward base travel < "
    f"evaluate.walk_distance, or fewer than {WALK_TOUCHDOWNS} touchdowns (not counted as "
    "holding). Not applied to C6-C8 (about walking) and C9 (standing still does not pitch "
    "the feet).",
    "**does not hold**: the medians do not order as claimed.",
    f"C1: holds when the baseline's median is within a factor {C1_FACTOR:g} of the paper's "
    "number, both parts (angular directly; linear in the authors' world representation). C4 "
    "and C9's trend use the seed medians.",
    "Metrics: velocity level (the authors' code) = sole velocities from the file's predicted "
    "joint velocities (the data's: the joints' differences) with the base velocity that holds "
    "the lower foot still, i.e. how the predicted velocities move the other foot while both "
    "are down; position level = from finite differences of the poses alone, i.e. how the feet "
    "of the trajectory a robot would track move. The linear part in "
    "evaluate.foot_velocity_frame unless it says world (the authors' inertial-fixed one); the "
    "angular part is the same in both.",
    "Row D: the retargeted data the models learn from, measured the same way "
    "(pimann.evaluate.data_reference): a reference level, no status.",
]


@dataclasses.dataclass
class Claim:
    id: str
    claim: str  # the paper's statement
    paper: str  # the paper's evidence (figure, numbers)
    figure: str  # our figure (paper_figures/<name>)
    ours: str = ""  # our numbers
    status: str = ""  # HOLDS | WITHIN_SPREAD | STANDS_STILL | FAILS | NOT_COMPARABLE
    reason: str = ""
    metric: str = ""  # what it measures


def fmt(value: float | None) -> str:
    return "n/a" if value is None or not np.isfinite(value) else f"{value:.3g}"


class SeedData:
    """Seed values of one scenario, by model, for the claims."""

    def __init__(self, frame: pd.DataFrame, scenario: str, representation: str):
        self.frame = frame[frame["scenario"] == scenario]
        self.scenario = scenario
        self.models = pi_models(frame)
        self.representation = representation

    def values(self, model: str | None, steering: bool, metric: str) -> np.ndarray:
        if model is None or metric not in self.frame:
            return np.array([])
        rows = select_rows(self.frame, self.scenario, steering, model=model)
        return rows[metric].astype(float).dropna().to_numpy()

    def median(self, model: str | None, steering: bool, metric: str) -> float | None:
        values = self.values(model, steering, metric)
        return float(np.median(values)) if len(values) else None

    def model(self, weight: float) -> str | None:
        return self.models.get(float(weight))

    def walk_fraction(self, weight: float, steering: bool) -> float | None:
        """The share of a weight's seeds whose rollout walks (None: no rollout)."""
        values = self.values(self.model(weight), steering, "walks")
        return float(np.mean(values)) if len(values) else None

    def still_seeds(self, model: str | None, steering: bool) -> list[int]:
        if model is None or "walks" not in self.frame:
            return []
        rows = select_rows(self.frame, self.scenario, steering, model=model)
        return sorted(int(s) for s in rows.loc[rows["walks"].astype(float) < 0.5, "seed"])


def velocity_level_cause(data: SeedData, weights: Sequence[float]) -> str:
    """What a failing velocity-level sliding claim reads beside: the baseline and the PI
    `weights` on the position level (the poses alone) and their double-support share (the
    velocity level holds the lower foot: only the other one slides, while both are down),
    seed medians of the unsteered runs."""
    models = [("baseline", BASELINE)] + [(f"w={weight_label(w)}", data.model(w)) for w in weights]

    def medians(metric: str) -> str:
        return ", ".join(
            f"{label} {fmt(data.median(model, False, metric))}" for label, model in models
        )

    return (
        f"; position level: {medians('support_rmse_linear_position_total')}; double support: "
        f"{medians('double_support_fraction')}"
    )


# train.pi_gradient values that hold the predicted configuration out of L_B's gradient
# (pimann.learn.training_loss, a torch module the claims do not import; a test ties the two), the
# way by which a large w tips the support foot onto its heel
CONFIGURATION_HELD = ("base", "joint_velocities")


def configuration_held_cause(pi_gradient: str) -> str:
    """C9's cause when `pi_gradient` keeps L_B from tipping the feet ('' when it does not)."""
    if pi_gradient not in CONFIGURATION_HELD:
        return ""
    return (
        f"; train.pi_gradient {pi_gradient} holds the configuration out of L_B's gradient, "
        "by which it would tip the feet onto their heels"
    )


def order(low: np.ndarray, high: np.ndarray) -> str:
    """Whether `low` < `high` over the seeds: separated ranges, medians only, or not at all."""
    if low.max() < high.min():
        return HOLDS
    return WITHIN_SPREAD if np.median(low) < np.median(high) else FAILS


def combine(orders: Iterable[str]) -> str:
    orders = list(orders)
    return next((s for s in (FAILS, WITHIN_SPREAD) if s in orders), HOLDS)


def span(values: np.ndarray) -> str:
    text = fmt(float(np.median(values)))
    return text if len(values) < 2 else f"{text} [{fmt(values.min())}-{fmt(values.max())}]"


def missing(claim: Claim, what: str) -> Claim:
    return dataclasses.replace(
        claim, ours="n/a", status=NOT_COMPARABLE, reason=f"no rollouts for {what}"
    )


def stands_still(
    data: SeedData, claim: Claim, favoured: Iterable[tuple[str | None, bool]]
) -> Claim:
    """A claim that holds with a favoured model standing still in some seed: STANDS_STILL."""
    if claim.status not in (HOLDS, WITHIN_SPREAD):
        return claim
    still = [
        f"{model}{' steered' if steering else ''} seed{'s' * (len(seeds) > 1)} "
        f"{', '.join(map(str, seeds))}"
        for model, steering in favoured
        if (seeds := data.still_seeds(model, steering))
    ]
    if not still:
        return claim
    still_text = "; ".join(still)
    reason = f"{claim.reason}; but {still_text} do not walk (travel < walk_distance or no steps)"
    return dataclasses.replace(claim, status=STANDS_STILL, reason=reason)


def data_claim(reference: dict[str, Any] | None) -> Claim | None:
    """Row D of claims.md: the retargeted data's own level (pimann.evaluate.data_reference)."""
    if not reference:
        return None

    def level(name: str, suffix: str) -> str:
        def value(metric: str) -> str:
            return fmt(reference_value(reference, f"support_rmse_{metric}_total", name))

        return (
            f"linear {value('linear' + suffix)} (world {value('linear' + suffix + '_world')}), "
            f"angular {value('angular' + suffix)}"
        )

    def liftoff(name: str) -> str:
        share = reference_value(reference, "support_rmse_linear_position_liftoff_share", name)
        frames = reference_value(reference, "contact_liftoff_frames_share", name)
        return f"; lift-off share {fmt(share)} (of {fmt(frames)} of the contact frames)"

    parts = []
    for name in ("all", "test"):
        subset = reference.get(name) or {}
        parts.append(
            f"{name} clips ({subset.get('used', 0)} of {subset.get('clips', 0)}): velocity level "
            f"{level(name, '')}; position level {level(name, '_position')}{liftoff(name)}"
        )
    differences = reference.get("joint_velocities") == "differences"
    return Claim(
        "D", reference.get("label", "data"), "- (the authors' data is not public)", RMSE_FIGURE,
        "; ".join(parts), REFERENCE,
        f"per clip: contact-masked RMS (evaluate rule) over forward-walking frames, per "
        f"{reference.get('frames')} frames; median over clips with >= "
        f"{reference.get('min_forward_frames')} forward frames"
        + ("; the data's joint velocities: the joints' differences" if differences else ""),
        f"{VELOCITY} and {POSITION}",
    )  # fmt: skip


def claims_markdown(
    claims: Sequence[Claim], provenance: dict[str, Any], reference: dict[str, Any] | None = None
) -> str:
    """claims.md: a provenance header with the rules, the data's row, one row per claim."""
    counts = {s: sum(c.status == s for c in claims) for s in (HOLDS, WITHIN_SPREAD, STANDS_STILL)}
    head = [
        "<!-- generated by `dvc repro evaluate` (pimann.evaluate.claims); do not edit -->",
        f"<!-- provenance: {json.dumps(_header_provenance(provenance), sort_keys=True)} -->",
        "",
        "# The paper's claims on our data",
        "",
        f"Profile **{provenance.get('profile')}**, {provenance.get('epochs')} epochs, "
        f"{provenance.get('clips')} clips, seeds {provenance.get('seeds')}, "
        f"scenario `{provenance.get('scenario')}`. Numbers: the seed median [min-max].",
        "",
        f"**{counts[HOLDS]} of {len(claims)} claims hold**; {counts[WITHIN_SPREAD]} hold within "
        f"the seed spread, {counts[STANDS_STILL]} only with a model standing still.",
        "",
        *(f"- {rule}" for rule in RULES),
        "",
        "| id | claim (paper) | paper | metric | ours | our figure | status | why |",
        "|---|---|---|---|---|---|---|---|",
    ]
    row = data_claim(reference)
    rows = [
        [c.id, c.claim, c.paper, c.metric, c.ours,
         f"paper_figures/{c.figure}.pdf" if c.figure != "-" else "-", f"**{c.status}**", c.reason]
        for c in ([row] if row else []) + list(claims)
    ]  # fmt: skip
    cells = [[text.replace("|", "\\|").replace("\n", " ") for text in r] for r in rows]
    return "\n".join(head + [f"| {' | '.join(r)} |" for r in cells]) + "\n"


def _header_provenance(provenance: dict[str, Any]) -> dict[str, Any]:
    return {k: provenance.get(k) for k in ("profile", "epochs", "clips", "max_takes", "seeds")}
