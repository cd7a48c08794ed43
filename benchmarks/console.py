"""Event -> WebSocket client latency of ``mmexec serve``.

Runs the service as ``mmexec serve`` does (the tick loop, uvicorn on a loopback socket
in its thread) with ``trees/demo_mock.yaml`` on ``config/mock.yaml``, connects a
WebSocket client (the ``websockets`` library, its own thread and event loop) to
``/api/stream?topics=event``, submits requests over HTTP, and measures for every event
record the time from the moment the event log wrote it (``time.perf_counter()`` in the
runner's record listener, before it is handed to the streams) to the moment the client
received it. Two workloads:

* ``paced``: each tick waits for its period of wall time, as the robot's wall clock does
  at the config's 20 Hz (the headline);
* ``burst``: the mock's stepped clock unpaced, ticks as fast as the CPU goes (thousands
  of records a second), the worst case for queueing.

Prints per workload the count, median, 95th percentile and maximum [ms], and as its last
line ``event_latency_ms: X``, the paced median. Target: <= 50 ms.

Usage: ``python benchmarks/console.py [--requests 1] [--burst-requests 20]``.
"""

from __future__ import annotations

import argparse
import asyncio
import io
import json
import statistics
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

import websockets

from mmexec.drivers.interfaces import Robot
from mmexec.executive.runner import RunOptions
from mmexec.executive.serve.app import create_app
from mmexec.executive.serve.server import BindAddress, ServerThread, open_socket
from mmexec.executive.serve.service import ServeRunner, Service

ROOT = Path(__file__).resolve().parents[1]
MISSION = ROOT / "trees" / "demo_mock.yaml"
CONFIG = ROOT / "config" / "mock.yaml"


class StampedRunner(ServeRunner):
    """Notes when each record was written, before the streams get it."""

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self.written: dict[int, float] = {}

    def _on_record(self, record: dict[str, Any]) -> None:
        self.written[record["seq"]] = time.perf_counter()
        super()._on_record(record)


def _post(url: str, body: Any = None) -> Any:
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, method="POST", headers={"content-type": "application/json"})
    with urllib.request.urlopen(req, timeout=60) as r:
        return json.loads(r.read())


def _get(url: str) -> Any:
    with urllib.request.urlopen(url, timeout=60) as r:
        return json.loads(r.read())


def measure(requests: int, paced: bool) -> list[float]:
    """Latencies [ms] of every event record of ``requests`` demo requests."""
    service = Service()
    with tempfile.TemporaryDirectory() as tmp:
        runner = StampedRunner(RunOptions(mission=MISSION, config=CONFIG, log_path=Path(tmp) / "events.jsonl"),
                               service, out=io.StringIO(), err=io.StringIO())
        runner.prepare()
        if paced:
            def pace(robot: Robot, period: float) -> None:
                time.sleep(period)  # the robot's wall clock: one period per tick
            runner.add_tick_hook(pace)
        sock = open_socket(BindAddress("127.0.0.1", 0))
        server = ServerThread(create_app(service), sock)
        server.start()
        base = f"http://127.0.0.1:{sock.getsockname()[1]}"
        received: dict[int, float] = {}
        ready = threading.Event()
        done = threading.Event()

        async def client() -> None:
            async with websockets.connect(base.replace("http", "ws", 1) + "/api/stream?topics=event",
                                          max_size=None) as ws:
                ready.set()
                while not done.is_set():
                    try:
                        text = await asyncio.wait_for(ws.recv(), 0.2)
                    except TimeoutError:
                        continue
                    now = time.perf_counter()
                    msg = json.loads(text)
                    if msg["type"] == "event":
                        received[msg["data"]["seq"]] = now

        reader = threading.Thread(target=asyncio.run, args=(client(),), daemon=True)
        reader.start()
        ready.wait(30)
        loop = threading.Thread(target=runner.run, daemon=True)
        loop.start()
        try:
            ids = [_post(f"{base}/api/requests", {"item": i % 5 + 1})["id"] for i in range(requests)]
            while _get(f"{base}/api/requests/{ids[-1]}")["state"] in ("queued", "running"):
                time.sleep(0.05)
            _post(f"{base}/api/stop")
            loop.join(60)
            time.sleep(0.2)  # the last records reach the client
        finally:
            done.set()
            reader.join(5)
            server.stop()
            sock.close()
    lost = [s for s in runner.written if s not in received]
    if lost:
        raise SystemExit(f"console benchmark: {len(lost)} of {len(runner.written)} records never reached the client")
    return [(received[s] - t) * 1000.0 for s, t in runner.written.items()]


def _report(name: str, ms: list[float]) -> float:
    ms = sorted(ms)
    med = statistics.median(ms)
    p95 = ms[int(0.95 * (len(ms) - 1))]
    print(f"{name}: {len(ms)} events, median {med:.2f} ms, p95 {p95:.2f} ms, max {ms[-1]:.2f} ms")
    return med


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--requests", type=int, default=1,
                    help="demo requests in the paced run (each about 31 s of clock, so of wall time when paced)")
    ap.add_argument("--burst-requests", type=int, default=20, help="demo requests in the unpaced run")
    args = ap.parse_args()
    _report("burst (stepped clock, unpaced)", measure(args.burst_requests, paced=False))
    paced = _report("paced (20 Hz wall clock)", measure(args.requests, paced=True))
    print(f"event_latency_ms: {paced:.2f}")


if __name__ == "__main__":
    main()
