"""Counts of the meshing fuzz cases run in this session, printed by tests/conftest.py."""
from collections import Counter

COUNTS: Counter = Counter()


def record(kind: str, outcome: str) -> None:
    COUNTS[(kind, outcome)] += 1


def summary() -> str | None:
    if not COUNTS:
        return None
    total = sum(COUNTS.values())
    kinds = sorted({k for k, _ in COUNTS})
    parts = []
    for kind in kinds:
        ok, error = COUNTS[(kind, "ok")], COUNTS[(kind, "error")]
        other = sum(v for (k, o), v in COUNTS.items() if k == kind and o not in ("ok", "error"))
        parts.append(f"{kind}: {ok} meshed, {error} refused" + (f", {other} FAILED" if other else ""))
    return f"mesh fuzzing: {total} cases run ({'; '.join(parts)})"
