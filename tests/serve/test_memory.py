"""1000 requests through the API on the mock backend: memory does not grow (tracemalloc,
at most 10 % over the level after a warm-up) and every request is accounted for in the
event log (queued once, ended once, in order, all successful).

The service runs in a fresh interpreter that starts tracemalloc before importing
anything, so the level measured is the whole service's (the executive, FastAPI, the
mission, the robot), not whatever an earlier test in the session left unallocated.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tracemalloc
from pathlib import Path
from typing import Any

WARMUP = 200
REQUESTS = 1000
BATCH = 100  # submitted at once, then waited for (the queue holds at most serve.max_queue)


def _serve_batches(svc: Any, first_item: int, count: int) -> None:
    """Submit ``count`` requests (items from ``first_item``) in batches, waiting for each
    batch; nothing per request is kept on the test's side (that would be growth too)."""
    for start in range(0, count, BATCH):
        last = 0
        for i in range(min(BATCH, count - start)):
            last = svc.client.post("/api/requests", json={"item": first_item + start + i}).json()["id"]
        svc.finished(last)


def _worker(folder: Path) -> dict[str, Any]:
    """In the fresh interpreter: serve WARMUP then REQUESTS requests; the traced memory
    after each, the exit code and the log's path."""
    import gc
    from collections import deque

    tracemalloc.start()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from conftest import MISSIONS, MOCK, Live

    svc = Live(MISSIONS / "quick.yaml", MOCK, folder / "events.jsonl")
    svc.out.lines = deque(maxlen=50)  # the console's tail: bounded, filled during the warm-up
    _serve_batches(svc, 0, WARMUP)
    gc.collect()
    baseline = tracemalloc.get_traced_memory()[0]
    _serve_batches(svc, WARMUP, REQUESTS)
    gc.collect()
    after = tracemalloc.get_traced_memory()[0]
    counts = svc.service.status()["counts"]
    code = svc.close()
    return {"baseline": baseline, "after": after, "code": code, "counts": counts, "log": str(svc.log_path)}


def test_thousand_requests_no_growth_all_logged(tmp_path: Path) -> None:
    from mmexec.executive.eventlog import read_log

    r = subprocess.run([sys.executable, __file__, str(tmp_path)], capture_output=True, text=True, timeout=900,
                       check=False)
    assert r.returncode == 0, r.stderr
    data = json.loads(r.stdout.strip().splitlines()[-1])
    baseline, after = data["baseline"], data["after"]
    assert after <= baseline * 1.10, f"traced memory grew from {baseline} to {after} bytes"
    assert data["code"] == 0
    total = WARMUP + REQUESTS
    assert data["counts"] == {"accepted": total, "served": total, "succeeded": total, "failed": 0, "dropped": 0}
    records = read_log(data["log"])
    every = list(range(1, total + 1))
    assert [r["id"] for r in records if r["event"] == "request_queued"] == every
    ends = [r for r in records if r["event"] == "request_end"]
    assert [r["id"] for r in ends] == [r["index"] for r in ends] == every
    assert {r["outcome"] for r in ends} == {"success"}
    assert [r["request"]["item"] for r in ends] == list(range(total))
    assert not [r for r in records if r["event"] == "request_dropped"]
    run_end = records[-1]
    assert run_end["event"] == "run_end" and run_end["served"] == run_end["succeeded"] == total


if __name__ == "__main__":
    print(json.dumps(_worker(Path(sys.argv[1]))))
