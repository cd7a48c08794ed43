"""Detection and grasp-point benchmark (issue 15; paper locobot-holistic-planning-dangerous-objects).

1. Grasp-point error against the true centre of mass over analytically rendered RGB-D
   scenes (:mod:`mmexec.skills.perception.synthetic_objects`): one upright box or
   cylinder (sides 3-12 cm, heights 3-15 cm, random yaw) on the floor, a table or a
   shelf board (support 0-0.75 m high), 0.45-1.0 m in front of a LoCoBot-like camera
   (0.53-0.59 m high, D435 stand-in 640x480, f = 590 px) that points near it. Depth
   spoilt like a stereo camera (2 mm/m noise, half spatially correlated; 5 % holes, a
   hole over the box centre in a fifth of the scenes; mixed pixels at edges). Boxes: the
   object's exact image box, and that box with each edge moved by a normal error of
   5 % of its side (a detector's localisation error). Compared: the paper's grasp point
   (the box centre pixel at its depth, III-C), ours without the item's size, ours with
   it (the catalogue).
2. Milliseconds per 640x480 frame for each detector backend: the classical colour
   detector, and the ONNX backend (letterbox, cv2.dnn forward, decoding, NMS) on
   YOLOv5n and YOLOv5s graphs built here with onnx.helper: Ultralytics' v6 architecture
   (Conv+SiLU, C3, SPPF, PANet, Detect with the export's in-graph decoding; output
   (1, 25200, 85)) with random weights, so the cost is the real model's, the boxes are
   not (the paper: YOLOv5s, 121 ms on the robot's i3-8th-gen CPU). The parameter count
   and GFLOPs printed check the graph against Ultralytics' figures (7.2 M, 16.5 GFLOPs
   for YOLOv5s at 640).

Prints the figures and LAST ``grasp_point_error_cm: X``: the median error of ours with
the item's size on the jittered boxes.

    .venv/bin/python benchmarks/detection.py [--scenes 200] [--seed 0] [--frames 20] [--models n,s]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from mmexec.drivers.interfaces import CameraFrame, CameraIntrinsics
from mmexec.skills.fetch_object.detector import PartsDetector
from mmexec.skills.perception.detector import ColourBlobDetector
from mmexec.skills.perception.grasp_point import GraspPointError, estimate_grasp
from mmexec.skills.perception.synthetic_objects import (
    SceneObject,
    look_at,
    object_box,
    render_scene,
    spoil_depth,
)
from mmexec.skills.perception.yolo import YoloConfig, load_yolo

K = CameraIntrinsics.from_fov(640, 480, 0.994837)
COCO = tuple(f"class{i}" for i in range(80))


def machine() -> str:
    cpu = "unknown CPU"
    if os.path.exists("/proc/cpuinfo"):
        with open("/proc/cpuinfo") as f:
            cpu = next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), cpu)
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    return (f"machine: {platform.machine()} {cpu}, nproc {os.cpu_count()}, python {platform.python_version()}, "
            f"numpy {np.__version__}, opencv {cv2.__version__} ({cv2.getNumThreads()} threads), load {load}")


# --------------------------------------------------------------------------- YOLOv5 graph


class _Builder:
    """Builds a YOLOv5 (v6.0+) ONNX graph layer by layer, counting parameters and MACs."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.nodes: list[onnx.NodeProto] = []
        self.inits: list[onnx.TensorProto] = []
        self.params = 0
        self.macs = 0
        self._n = 0

    def name(self, base: str) -> str:
        self._n += 1
        return f"{base}_{self._n}"

    def const(self, value: np.ndarray, base: str = "c") -> str:
        n = self.name(base)
        self.inits.append(numpy_helper.from_array(value, n))
        return n

    def op(self, op: str, inputs: list[str], **attrs: object) -> str:
        out = self.name(op.lower())
        self.nodes.append(helper.make_node(op, inputs, [out], **attrs))
        return out

    def conv(self, x: tuple[str, int, int], c2: int, k: int, s: int = 1, act: bool = True,
             bias: np.ndarray | None = None, pad: int | None = None) -> tuple[str, int, int]:
        """Conv (BN folded in) + SiLU; ``x`` is (tensor, channels, size); ``pad``
        default ``k // 2``."""
        name, c1, hw = x
        w = (self.rng.standard_normal((c2, c1, k, k)) * math.sqrt(1.0 / (c1 * k * k))).astype(np.float32)
        b = bias if bias is not None else np.zeros(c2, np.float32)
        p = k // 2 if pad is None else pad
        y = self.op("Conv", [name, self.const(w, "w"), self.const(b.astype(np.float32), "b")],
                    kernel_shape=[k, k], strides=[s, s], pads=[p, p, p, p])
        out_hw = (hw + 2 * p - k) // s + 1
        self.params += w.size + c2
        self.macs += c2 * c1 * k * k * out_hw * out_hw
        if act:
            y = self.op("Mul", [y, self.op("Sigmoid", [y])])
        return y, c2, out_hw

    def bottleneck(self, x: tuple[str, int, int], c: int, shortcut: bool) -> tuple[str, int, int]:
        y = self.conv(self.conv(x, c, 1), c, 3)
        return (self.op("Add", [x[0], y[0]]), c, y[2]) if shortcut else y

    def c3(self, x: tuple[str, int, int], c2: int, n: int, shortcut: bool = True) -> tuple[str, int, int]:
        c_ = c2 // 2
        a = self.conv(x, c_, 1)
        for _ in range(n):
            a = self.bottleneck(a, c_, shortcut)
        b = self.conv(x, c_, 1)
        return self.conv((self.op("Concat", [a[0], b[0]], axis=1), 2 * c_, x[2]), c2, 1)

    def sppf(self, x: tuple[str, int, int], c2: int) -> tuple[str, int, int]:
        c_ = x[1] // 2
        y = self.conv(x, c_, 1)
        pools = [y[0]]
        for _ in range(3):
            pools.append(self.op("MaxPool", [pools[-1]], kernel_shape=[5, 5], strides=[1, 1], pads=[2, 2, 2, 2]))
        return self.conv((self.op("Concat", pools, axis=1), 4 * c_, y[2]), c2, 1)

    def up(self, x: tuple[str, int, int]) -> tuple[str, int, int]:
        scales = self.const(np.array([1, 1, 2, 2], np.float32), "scales")
        return self.op("Resize", [x[0], "", scales], mode="nearest"), x[1], 2 * x[2]

    def cat(self, a: tuple[str, int, int], b: tuple[str, int, int]) -> tuple[str, int, int]:
        return self.op("Concat", [a[0], b[0]], axis=1), a[1] + b[1], a[2]


#: Ultralytics' anchors (pixels) of P3/8, P4/16, P5/32
ANCHORS = ((10, 13, 16, 30, 33, 23), (30, 61, 62, 45, 59, 119), (116, 90, 156, 198, 373, 326))


def build_yolov5(path: Path, variant: str, *, nc: int = 80, size: int = 640, seed: int = 0) -> tuple[int, float]:
    """Write a YOLOv5 ``variant`` (n, s, m) graph with random weights to ``path``; returns
    (parameters, GFLOPs as Ultralytics counts them: 2 x multiply-accumulates)."""
    depth, width = {"n": (0.33, 0.25), "s": (0.33, 0.50), "m": (0.67, 0.75)}[variant]

    def ch(c: int) -> int:                                                # channels, multiples of 8
        return int(math.ceil(c * width / 8) * 8)

    def nd(n: int) -> int:                                                # bottlenecks per C3
        return max(round(n * depth), 1)

    g = _Builder(np.random.default_rng(seed))
    x = ("images", 3, size)
    x = g.conv(x, ch(64), 6, 2, pad=2)
    x = g.conv(x, ch(128), 3, 2)
    x = g.c3(x, ch(128), nd(3))
    x = g.conv(x, ch(256), 3, 2)
    p3 = g.c3(x, ch(256), nd(6))
    x = g.conv(p3, ch(512), 3, 2)
    p4 = g.c3(x, ch(512), nd(9))
    x = g.conv(p4, ch(1024), 3, 2)
    x = g.c3(x, ch(1024), nd(3))
    x = g.sppf(x, ch(1024))
    h10 = g.conv(x, ch(512), 1)
    x = g.c3(g.cat(g.up(h10), p4), ch(512), nd(3), False)
    h14 = g.conv(x, ch(256), 1)
    out3 = g.c3(g.cat(g.up(h14), p3), ch(256), nd(3), False)
    out4 = g.c3(g.cat(g.conv(out3, ch(256), 3, 2), h14), ch(512), nd(3), False)
    out5 = g.c3(g.cat(g.conv(out4, ch(512), 3, 2), h10), ch(1024), nd(3), False)
    no = 5 + nc
    parts = []
    for level, (feat, stride) in enumerate(((out3, 8), (out4, 16), (out5, 32))):
        bias = np.zeros((3, no), np.float32)
        bias[:, 4] = math.log(8 / (size / stride) ** 2)                  # Ultralytics' initial objectness
        bias[:, 5:] = math.log(0.6 / (nc - 0.99))
        y, _, n = g.conv(feat, 3 * no, 1, act=False, bias=bias.ravel())
        y = g.op("Reshape", [y, g.const(np.array([1, 3, no, n, n], np.int64), "shape")])
        y = g.op("Sigmoid", [g.op("Transpose", [y], perm=[0, 1, 3, 4, 2])])     # (1, 3, n, n, no)
        gy, gx = np.meshgrid(np.arange(n, dtype=np.float32), np.arange(n, dtype=np.float32), indexing="ij")
        grid = (np.stack([gx, gy], -1)[None, None] - 0.5).astype(np.float32)   # (1, 1, n, n, 2)
        anchors = np.array(ANCHORS[level], np.float32).reshape(1, 3, 1, 1, 2)
        two = g.const(np.array(2.0, np.float32), "two")
        split = g.const(np.array([2, 2, no - 4], np.int64), "split")
        xy, wh, conf = (g.name("xy"), g.name("wh"), g.name("conf"))
        g.nodes.append(helper.make_node("Split", [y, split], [xy, wh, conf], axis=4))
        xy = g.op("Mul", [g.op("Add", [g.op("Mul", [xy, two]), g.const(grid, "grid")]),
                          g.const(np.array(stride, np.float32), "stride")])
        wh2 = g.op("Mul", [wh, two])
        wh = g.op("Mul", [g.op("Mul", [wh2, wh2]), g.const(anchors, "anchors")])
        y = g.op("Concat", [xy, wh, conf], axis=4)
        parts.append(g.op("Reshape", [y, g.const(np.array([1, 3 * n * n, no], np.int64), "shape")]))
    g.nodes.append(helper.make_node("Concat", parts, ["output0"], axis=1))
    n_out = sum(3 * (size // s) ** 2 for s in (8, 16, 32))
    graph = helper.make_graph(g.nodes, f"yolov5{variant}_random",
                              [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, size, size])],
                              [helper.make_tensor_value_info("output0", TensorProto.FLOAT, [1, n_out, no])], g.inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    helper.set_model_props(model, {"names": repr(dict(enumerate(COCO[:nc]))), "stride": "32"})
    onnx.checker.check_model(model)
    path.write_bytes(model.SerializeToString())
    return g.params, 2.0 * g.macs / 1e9


# --------------------------------------------------------------------------- scenes


@dataclass(frozen=True)
class Scene:
    frame: CameraFrame
    truth: np.ndarray
    box: tuple[int, int, int, int]
    size: tuple[float, float, float]
    kind: str
    top_visible: bool


def _random_item(rng: np.random.Generator, centre_xy: tuple[float, float], support: float) -> SceneObject:
    h = float(rng.uniform(0.03, 0.15))
    colour = tuple(int(c) for c in rng.integers(30, 230, 3))
    if rng.random() < 0.35:
        d = float(2 * rng.uniform(0.02, 0.045))
        return SceneObject("cylinder", (*centre_xy, support + h / 2), (d, d, h), 0.0, colour)  # type: ignore[arg-type]
    sides = (float(rng.uniform(0.03, 0.12)), float(rng.uniform(0.03, 0.12)), h)
    return SceneObject("box", (*centre_xy, support + h / 2), sides, float(rng.uniform(-math.pi, math.pi)),  # type: ignore[arg-type]
                       colour)


def make_scene(rng: np.random.Generator) -> Scene | None:
    """One random scene (see the module doc), or None when the item is not wholly in
    view or too small."""
    cam_z = float(rng.uniform(0.53, 0.59))
    dist = float(rng.uniform(0.45, 1.0))
    bearing = float(rng.uniform(-0.35, 0.35))
    cx, cy = dist * math.cos(bearing), dist * math.sin(bearing)
    support = 0.0 if rng.random() < 0.2 else float(rng.uniform(0.2, 0.75))
    item = _random_item(rng, (cx, cy), support)
    objects = [item]
    if support > 0:                                                      # a table top or shelf board
        front = float(rng.uniform(0.05, 0.25))
        objects.append(SceneObject("box", (cx + 0.3 - front, cy, support - 0.01), (0.6, 1.0, 0.02),
                                   0.0, (140, 120, 95)))
    aim = (cx + float(rng.normal(0, 0.03)), cy + float(rng.normal(0, 0.05)), item.centre[2] + float(rng.normal(0, 0.03)))
    T = look_at((0.0, 0.0, cam_z), aim)
    view = render_scene(objects, T, K, support_z=0.0)
    box = object_box(view.labels, 0)
    if box is None or box[0] <= 0 or box[1] <= 0 or box[0] + box[2] >= K.width or box[1] + box[3] >= K.height:
        return None
    if int((view.labels == 0).sum()) < 400:
        return None
    depth = spoil_depth(view.depth, rng, noise_per_metre=0.002, holes=0.05, flying=0.5)
    if rng.random() < 0.2:                                               # a hole over the box centre
        u, v = box[0] + box[2] // 2, box[1] + box[3] // 2
        cv2.circle(depth, (u, v), int(max(3, 0.15 * min(box[2], box[3]))), float("nan"), -1)
    frame = CameraFrame(view.rgb, depth, K, 0.0, T)
    top = item.centre[2] + item.size[2] / 2
    return Scene(frame, np.asarray(item.centre), box, item.size, item.kind, cam_z > top + 0.01)


def jitter(box: tuple[int, int, int, int], rng: np.random.Generator, frac: float = 0.05) -> tuple[int, int, int, int]:
    """``box`` with each edge moved by a normal error of ``frac`` of its side [px]."""
    x, y, w, h = box
    x0, x1 = x + rng.normal(0, frac * w), x + w + rng.normal(0, frac * w)
    y0, y1 = y + rng.normal(0, frac * h), y + h + rng.normal(0, frac * h)
    x0, y0 = max(0, round(x0)), max(0, round(y0))
    x1, y1 = min(K.width, round(x1)), min(K.height, round(y1))
    return x0, y0, max(1, x1 - x0), max(1, y1 - y0)


# --------------------------------------------------------------------------- measurement


def _summary(errs: list[float]) -> str:
    if not errs:
        return "no estimates"
    a = np.asarray(errs) * 100.0
    return (f"median {np.median(a):5.2f} cm, p90 {np.quantile(a, 0.9):5.2f}, p95 {np.quantile(a, 0.95):5.2f}, "
            f"max {a.max():5.2f} (n {len(a)})")


def grasp_benchmark(scenes: list[Scene], rng: np.random.Generator) -> float:
    """Print the grasp-point errors; returns the headline median [cm]."""
    methods: dict[str, Callable[[Scene, tuple[int, int, int, int]], np.ndarray]] = {
        "paper (box centre depth)": lambda s, b: estimate_grasp(s.frame, b, size=s.size).surface,
        "ours, no size": lambda s, b: estimate_grasp(s.frame, b).centre,
        "ours, catalogue size": lambda s, b: estimate_grasp(s.frame, b, size=s.size).centre,
    }
    boxes = {"exact box": [s.box for s in scenes], "jittered box (5 %)": [jitter(s.box, rng) for s in scenes]}
    headline = math.nan
    for box_name, bxs in boxes.items():
        print(f"\n{box_name}:")
        for name, fn in methods.items():
            errs: dict[str, list[float]] = {"all": [], "top seen": [], "top hidden": []}
            times, failed = [], 0
            for s, b in zip(scenes, bxs):
                t0 = time.process_time()
                try:
                    p = fn(s, b)
                except GraspPointError:
                    failed += 1
                    continue
                times.append(time.process_time() - t0)
                e = float(np.linalg.norm(p - s.truth))
                errs["all"].append(e)
                errs["top seen" if s.top_visible else "top hidden"].append(e)
            print(f"  {name:26s} {_summary(errs['all'])}, failed {failed}, "
                  f"CPU {statistics.median(times) * 1e3:.1f} ms median per estimate")
            for part in ("top seen", "top hidden"):
                print(f"  {'':26s}   {part:10s}: {_summary(errs[part])}")
            if name == "ours, catalogue size" and box_name.startswith("jittered"):
                headline = float(np.median(errs["all"]) * 100.0)
    return headline


def _time_detect(detect: Callable[[np.ndarray], object], frames: list[np.ndarray]) -> tuple[float, float]:
    """(median wall ms, median CPU ms) of ``detect`` per frame, after one warm-up call."""
    detect(frames[0])
    wall, cpu = [], []
    for f in frames:
        t0, c0 = time.perf_counter(), time.process_time()
        detect(f)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return statistics.median(wall) * 1e3, statistics.median(cpu) * 1e3


def detector_benchmark(frames: list[np.ndarray], variants: list[str]) -> None:
    print(f"\ndetectors, ms per 640x480 frame (median over {len(frames)} rendered frames; wall / process CPU):")
    colour = ColourBlobDetector()
    w, c = _time_detect(colour.detect, frames)
    print(f"  classical colour/shape (ColourBlobDetector)         {w:7.1f} / {c:7.1f}")
    w, c = _time_detect(PartsDetector().detect, frames)
    print(f"  classical parts of the sim object set (PartsDetector) {w:5.1f} / {c:7.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        for variant in variants:
            path = Path(tmp) / f"yolov5{variant}.onnx"
            params, gflops = build_yolov5(path, variant)
            det = load_yolo(YoloConfig(str(path)))
            w, c = _time_detect(det.detect, frames)
            fw, fc = _time_detect(det.infer, frames)
            print(f"  ONNX YOLOv5{variant} ({params / 1e6:.2f} M params, {gflops:.1f} GFLOPs, {det.layout}, "
                  f"{det.input_size[0]}x{det.input_size[1]}): detect {w:7.1f} / {c:7.1f}, "
                  f"letterbox+forward {fw:7.1f} / {fc:7.1f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--frames", type=int, default=20, help="frames timed per detector")
    ap.add_argument("--models", default="n,s", help="YOLOv5 variants to time (n, s, m; empty: none)")
    args = ap.parse_args(argv)
    print(machine())
    rng = np.random.default_rng(args.seed)
    scenes: list[Scene] = []
    tries = 0
    while len(scenes) < args.scenes:
        tries += 1
        s = make_scene(rng)
        if s is not None:
            scenes.append(s)
    kinds = {k: sum(s.kind == k for s in scenes) for k in ("box", "cylinder")}
    print(f"scenes: {len(scenes)} ({tries - len(scenes)} redrawn: item not wholly in view), {kinds['box']} boxes, "
          f"{kinds['cylinder']} cylinders, top seen in {sum(s.top_visible for s in scenes)}; "
          "depth 2 mm/m noise, 5 % holes, a hole over the box centre in ~20 %, mixed pixels at edges")
    headline = grasp_benchmark(scenes, rng)
    variants = [v for v in args.models.split(",") if v]
    detector_benchmark([s.frame.rgb for s in scenes[: args.frames]], variants)
    print(machine())
    print(f"grasp_point_error_cm: {headline:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
