"""1000 requests through the API on the mock backend: memory does not grow (tracemalloc,
at most 10 % over the level after a warm-up) and every request is accounted for in the
event log (queued once, ended once, in order, all successful)."""

from __future__ import annotations

import gc
import tracemalloc
from collections import deque
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


def test_thousand_requests_no_growth_all_logged(live: Any) -> None:
    tracemalloc.start()
    try:
        svc = live("quick")
        svc.out.lines = deque(svc.out.lines, maxlen=50)  # the console's tail fills during the warm-up
        _serve_batches(svc, 0, WARMUP)
        gc.collect()
        baseline = tracemalloc.get_traced_memory()[0]
        _serve_batches(svc, WARMUP, REQUESTS)
        gc.collect()
        after = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    print(f"traced memory after warm-up {baseline} bytes, after {REQUESTS} more requests {after} bytes")
    assert after <= baseline * 1.10, f"traced memory grew from {baseline} to {after} bytes"
    assert svc.close() == 0
    every = list(range(1, WARMUP + REQUESTS + 1))
    queued = svc.records("request_queued")
    ends = svc.records("request_end")
    assert [r["id"] for r in queued] == every
    assert [r["index"] for r in ends] == every
    assert {r["outcome"] for r in ends} == {"success"}
    assert [r["request"]["item"] for r in ends] == list(range(WARMUP + REQUESTS))
    assert svc.records("request_dropped") == []
    run_end = svc.records("run_end")[0]
    assert run_end["served"] == run_end["succeeded"] == WARMUP + REQUESTS
    status = svc.service.status()["counts"]
    assert status == {"accepted": 1200, "served": 1200, "succeeded": 1200, "failed": 0, "dropped": 0}
