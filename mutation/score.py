"""Mutation score of a sampled cosmic-ray session, with a 95 % binomial CI, and the survivors.

Usage: ``python mutation/score.py SESSION.sqlite``. Score = killed / (killed + survived) over
the sampled mutants that ran; a timeout counts as killed (cosmic-ray's rule); incompetent
mutants (the test command could not start) are left out and counted. The interval is the
Clopper-Pearson interval of :func:`scipy.stats.binomtest`.
"""

from __future__ import annotations

import sys

from cosmic_ray.work_db import WorkDB, use_db
from cosmic_ray.work_item import TestOutcome, WorkerOutcome
from scipy.stats import binomtest


def main(argv: list[str]) -> int:
    killed = survived = other = 0
    survivors = []
    with use_db(argv[0], WorkDB.Mode.open) as db:
        not_reached = 0
        for item, result in db.completed_work_items:
            if result.worker_outcome == WorkerOutcome.SKIPPED:
                not_reached += result.output == "sample not reached"
                continue
            if result.test_outcome == TestOutcome.KILLED:
                killed += 1
            elif result.test_outcome == TestOutcome.SURVIVED:
                survived += 1
                survivors.append((item, result))
            else:
                other += 1
        pending = db.num_work_items - db.num_results
    n = killed + survived
    if n == 0:
        print("no mutant has run yet")
        return 1
    ci = binomtest(killed, n).proportion_ci(confidence_level=0.95)
    print(f"mutation score {killed}/{n} = {killed / n:.1%} (95 % CI {ci.low:.1%}-{ci.high:.1%}); "
          f"{other} incompetent/errored, {pending} pending, {not_reached} sampled but not reached")
    for item, result in survivors:
        m = item.mutations[0]
        print(f"\nSURVIVED {m.module_path}:{m.start_pos[0]} {m.operator_name} #{m.occurrence}")
        print("\n".join("    " + line for line in (result.diff or "").splitlines()
                        if line.startswith(("+", "-")) and not line.startswith(("+++", "---"))))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
