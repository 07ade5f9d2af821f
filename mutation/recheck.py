"""Prepare a sampled session for a re-check of its survivors (after tests were added).

Usage: ``python mutation/recheck.py SESSION.sqlite [PATH_KEYWORD ...]``, then ``cosmic-ray exec``
again. Surviving mutants (only those whose module path contains one of the keywords, when given)
become pending again; sampled mutants that never ran (the run was stopped) are marked skipped
with the reason ``"sample not reached"``, so the score is over a random subsample (cosmic-ray
runs the sample in random job-id order) and says how many were not reached.
"""

from __future__ import annotations

import sqlite3
import sys


def main(argv: list[str]) -> int:
    session, keywords = argv[0], argv[1:]
    con = sqlite3.connect(session)
    with con:
        unrun = [r[0] for r in con.execute(
            "SELECT job_id FROM work_items WHERE job_id NOT IN (SELECT job_id FROM work_results)")]
        con.executemany("INSERT INTO work_results (worker_outcome, output, test_outcome, diff, job_id) "
                        "VALUES ('SKIPPED', 'sample not reached', NULL, NULL, ?)", [(j,) for j in unrun])
        survivors = [(j, p) for j, p in con.execute(
            "SELECT r.job_id, m.module_path FROM work_results r JOIN mutation_specs m ON m.job_id = r.job_id "
            "WHERE r.test_outcome = 'SURVIVED'")]
        again = [j for j, p in survivors if not keywords or any(k in p for k in keywords)]
        con.executemany("DELETE FROM work_results WHERE job_id = ?", [(j,) for j in again])
    print(f"{session}: {len(unrun)} sampled mutants not reached (skipped); "
          f"{len(again)} of {len(survivors)} survivors pending again")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
