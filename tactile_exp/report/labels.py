"""The report's note on labels: which a job dropped (``labels.min_objects``) and which it
scored on trials of an object seen in training (a class of one object, split by trial), from
the tags each job's run carries (`tactile_exp.experiment.label_notes`)."""

from __future__ import annotations

from tactile_exp.report.runs import Group
from tactile_exp.tracking import Tracker


def label_notes(groups: list[Group], tracker: Tracker) -> str:
    """A markdown section listing, per configuration, its dropped and seen-object labels;
    empty when no job has any."""
    lines = []
    for g in groups:
        dropped, seen = set(), set()
        for run in g.runs.values():
            tags = tracker.client.get_run(run.run_id).data.tags
            dropped.update(tags.get("labels.dropped", "").split(" ")[:-1])  # last: min_objects
            seen.update(tags.get("labels.seen_object", "").split())
        if dropped:
            lines.append(
                f"- `{g.method}`: dropped by `labels.min_objects` (+/- objects): "
                f"{', '.join(sorted(dropped))}"
            )
        if seen:
            lines.append(
                f"- `{g.method}`: one object of a class, split by trial, so scored on trials "
                f"of an object seen in training: {', '.join(sorted(seen))}"
            )
    if not lines:
        return ""
    head = [
        "",
        "## Labels left out or scored on a seen object",
        "",
        "Labels a job dropped because a class had fewer objects than `labels.min_objects`, and",
        "labels whose positives or negatives are a single object: a trial-level split puts that",
        "object's trials on both sides, so its AUC is not about unseen objects.",
        "",
    ]
    return "\n".join(head + lines) + "\n"
