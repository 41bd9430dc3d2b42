"""The fault table (`python -m engine bench faults`): every bad input a user can give
`python -m engine reconstruct` ends with its documented exit code and a one-line message,
never a traceback, and changes nothing it should not."""

from engine.bench.faults import FAULTS, bench_faults


def test_every_fault_ends_as_documented():
    rows = bench_faults()
    assert len(rows) == len(FAULTS)
    bad = [row for row in rows if row["ok"] != "yes"]
    assert not bad, bad
    # not vacuous: the control succeeds and a bad input fails with its message
    assert rows[0]["exit"] == 0
    truncated = next(row for row in rows if row["fault"] == "a truncated JPEG")
    assert truncated["exit"] == 2 and "004.jpg is truncated" in truncated["message"]
