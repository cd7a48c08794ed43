from __future__ import annotations

import cv2
import numpy as np
import pytest

from mmexec.skills.perception.detector import (
    DEFAULT_CLASSES,
    ColourBlobDetector,
    ColourDetectorConfig,
    Detection,
    ObjectDetector,
    blob_confidence,
    colour_mask,
)

COLOURS = {"apple": (200, 25, 30), "yellow_ball": (235, 205, 30), "green_ball": (40, 170, 60),
           "blue_ball": (30, 70, 200)}


def _clutter(rng, h=480, w=640):
    """A cluttered, mostly unsaturated background: noise texture, grey-brown boxes, lines."""
    img = rng.integers(90, 160, (h, w, 1)).repeat(3, axis=2).astype(np.uint8)
    img = cv2.GaussianBlur(img, (0, 0), 2.0)
    for _ in range(25):
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        base = rng.integers(40, 200)
        col = tuple(int(np.clip(base + d, 0, 255)) for d in rng.integers(-25, 25, 3))
        if rng.random() < 0.6:
            cv2.rectangle(img, (x, y), (x + int(rng.integers(10, 120)), y + int(rng.integers(10, 80))), col, -1)
        else:
            cv2.line(img, (x, y), (int(rng.integers(0, w)), int(rng.integers(0, h))), col, int(rng.integers(1, 6)))
    return img


def _ball(img, centre, radius, rgb, light=(-0.4, -0.5, 0.77)):
    """A shaded sphere: ambient + Lambertian + a white specular spot, anti-aliased rim."""
    h, w = img.shape[:2]
    cx, cy = centre
    ys, xs = np.mgrid[0:h, 0:w].astype(float)
    dx, dy = (xs - cx) / radius, (ys - cy) / radius
    rho2 = dx * dx + dy * dy
    inside = rho2 < 1.0
    nz = np.sqrt(np.clip(1.0 - rho2, 0.0, 1.0))
    L = np.asarray(light) / np.linalg.norm(light)
    lam = np.clip(dx * L[0] + dy * L[1] + nz * L[2], 0.0, 1.0)
    Hv = (L + [0, 0, 1.0]) / np.linalg.norm(L + [0, 0, 1.0])
    spec = np.clip(dx * Hv[0] + dy * Hv[1] + nz * Hv[2], 0.0, 1.0) ** 40
    shade = (0.25 + 0.75 * lam)[..., None] * np.asarray(rgb, float) + 255.0 * 0.8 * spec[..., None]
    img[inside] = np.clip(shade[inside], 0, 255).astype(np.uint8)
    return img


def _iou(a, b):
    ax1, ay1, bx1, by1 = a[0] + a[2], a[1] + a[3], b[0] + b[2], b[1] + b[3]
    iw, ih = max(0, min(ax1, bx1) - max(a[0], b[0])), max(0, min(ay1, by1) - max(a[1], b[1]))
    inter = iw * ih
    return inter / (a[2] * a[3] + b[2] * b[3] - inter)


def _scene(seed):
    """Four balls (one per class) and three saturated distractors (a red box, a green leaf,
    a thick blue line), each in its own 160x160 cell of a cluttered 640x480 image."""
    rng = np.random.default_rng(seed)
    img = _clutter(rng)
    cells = rng.permutation(12)[:7]
    spots = [(int(160 * (k % 4) + 80 + rng.integers(-25, 26)), int(160 * (k // 4) + 80 + rng.integers(-25, 26)))
             for k in cells]
    truth = {}
    for (label, rgb), (cx, cy) in zip(COLOURS.items(), spots[:4]):
        r = int(rng.integers(15, 46))
        light = (rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6), 0.7)
        _ball(img, (cx, cy), r, rgb, light)
        truth[label] = (cx - r, cy - r, 2 * r, 2 * r)
    (bx, by), (lx, ly), (nx, ny) = spots[4:]
    cv2.rectangle(img, (bx - 30, by - 30), (bx + 30, by + 30), (210, 20, 25), -1)
    cv2.ellipse(img, (lx, ly), (50, 14), int(rng.integers(0, 180)), 0, 360, (50, 160, 50), -1)
    cv2.line(img, (nx - 60, ny + 5), (nx + 60, ny - 5), (30, 60, 210), 9)
    return img, truth, spots


def test_finds_each_ball_with_its_class_and_box_on_clutter():
    det: ObjectDetector = ColourBlobDetector()
    assert det.classes == ("apple", "yellow_ball", "green_ball", "blue_ball")
    for seed in range(6):
        img, truth, _ = _scene(seed)
        found = det.detect(img)
        assert sorted(d.label for d in found) == sorted(truth), found   # no distractor
        for d in found:
            assert _iou(d.box, truth[d.label]) > 0.85
            assert 0.8 < d.confidence <= 1.0
        assert [d.confidence for d in found] == sorted((d.confidence for d in found), reverse=True)


def test_shape_scores():
    def score(draw):
        m = np.zeros((200, 200), np.uint8)
        draw(m)
        contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        return blob_confidence(contours[0])

    disc = score(lambda m: cv2.circle(m, (100, 100), 40, 255, -1))
    square = score(lambda m: cv2.rectangle(m, (60, 60), (140, 140), 255, -1))
    half = score(lambda m: cv2.ellipse(m, (100, 100), (40, 40), 0, 0, 180, 255, -1))
    leaf = score(lambda m: cv2.ellipse(m, (100, 100), (60, 18), 20, 0, 360, 255, -1))
    assert disc > 0.85
    assert 0.4 < square < 0.55 and 0.3 < half < 0.5 and leaf < 0.3


def test_partly_hidden_ball_scores_lower():
    rng = np.random.default_rng(4)
    img = _ball(_clutter(rng), (300, 240), 40, COLOURS["apple"])
    det = ColourBlobDetector()

    def apples(image):
        return [d for d in det.detect(image) if d.label == "apple"]

    full = apples(img)
    cv2.rectangle(img, (315, 150), (400, 330), (120, 110, 100), -1)   # a post hides a third
    third = apples(img)
    cv2.rectangle(img, (300, 150), (400, 330), (120, 110, 100), -1)   # ... half
    assert len(full) == 1 and len(third) == 1
    assert full[0].confidence > 0.85 and third[0].confidence < full[0].confidence - 0.2
    assert apples(img) == []   # below the default threshold


def test_colour_mask_in_the_box():
    img, truth, spots = _scene(0)
    apple = DEFAULT_CLASSES[0]
    box = truth["apple"]
    m = colour_mask(img, apple, box)
    x, y, w, h = box
    assert not m[:y].any() and not m[y + h:].any() and not m[:, :x].any() and not m[:, x + w:].any()
    disc = np.zeros(m.shape, np.uint8)
    cv2.circle(disc, (x + w // 2, y + h // 2), w // 2, 1, -1)
    # most of the disc has the colour (the specular spot and the darkest rim need not)
    assert 0.85 < m[disc > 0].mean() and m[disc == 0].sum() < 0.05 * disc.sum()
    # without a box the red distractor is in the mask too
    assert colour_mask(img, apple)[spots[4][1], spots[4][0]]
    assert not colour_mask(img, apple, (700, 500, 10, 10)).any()


def test_errors():
    with pytest.raises(ValueError, match="HxWx3 uint8"):
        ColourBlobDetector().detect(np.zeros((10, 10), np.uint8))
    with pytest.raises(ValueError, match="min_confidence"):
        ColourBlobDetector(ColourDetectorConfig(min_confidence=2.0))
    bad = ColourDetectorConfig(classes=(DEFAULT_CLASSES[0], DEFAULT_CLASSES[0]))
    assert any("unique" in e for e in bad.validate())
    assert Detection("apple", 0.9, (1, 2, 3, 4)).box == (1, 2, 3, 4)
