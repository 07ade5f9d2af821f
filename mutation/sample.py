"""Keep a seeded random sample of a cosmic-ray session's mutants; mark the rest skipped.

Usage: ``python mutation/sample.py SESSION.sqlite [N] [SEED]`` after ``cosmic-ray init``.
A full run (about a thousand mutants, each running its module's tests) takes days on a shared
2-core machine; a simple random sample gives an unbiased estimate of the mutation score with a
binomial confidence interval (mutation/score.py).
"""

from __future__ import annotations

import random
import sys

from cosmic_ray.work_db import WorkDB, use_db
from cosmic_ray.work_item import WorkerOutcome, WorkResult


def main(argv: list[str]) -> int:
    session = argv[0]
    n = int(argv[1]) if len(argv) > 1 else 60
    seed = int(argv[2]) if len(argv) > 2 else 14
    with use_db(session, WorkDB.Mode.open) as db:
        items = sorted(db.pending_work_items, key=lambda w: w.job_id)
        # order by (module, line, operator, occurrence): job ids are random uuids
        items.sort(key=lambda w: (str(w.mutations[0].module_path), w.mutations[0].start_pos,
                                  w.mutations[0].operator_name, w.mutations[0].occurrence))
        keep = {w.job_id for w in random.Random(seed).sample(items, min(n, len(items)))}
        skip = [w.job_id for w in items if w.job_id not in keep]
        db.set_multiple_results(skip, WorkResult(worker_outcome=WorkerOutcome.SKIPPED,
                                                 output="not in the sample"))
    print(f"{session}: {len(items)} mutants, {len(keep)} kept (seed {seed}), {len(skip)} skipped")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
