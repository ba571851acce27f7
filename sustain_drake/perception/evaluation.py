"""Evaluation of body detection against the renderer's labels (issue 4, item 4). Pure numpy + cv2.

- :func:`cell_coverage`: fraction of each grid cell covered by given labels in a label image.
- :class:`CellTruth`: per-cell truth accumulated over an episode: a cell is *body* where the
  robot's pixels (arm and held tool) covered at least ``body_cover`` (10 %) of it in some frame,
  *background* where they never covered any pixel, and *ignored* in between. *Distractor* cells
  are background cells where the distractor's pixels appeared.
- :func:`mask_metrics`: precision, recall and IoU of a predicted body mask on that truth.
- :func:`detection_latencies`: per cell, the time from its first visible robot motion to its
  first detection.
- :class:`EpisodeEvaluator`: all of the above streamed over an episode, as a ``metrics.json``
  dictionary.
- :func:`draw_likelihood_map` / :func:`save_likelihood_png`: the likelihood map over the camera
  image, like the paper's Figs. 3-5 (red: body cells, shade ~ Σ_i ε_ij; blue: cells with ṡ_j > 0).
- :func:`draw_mask_vs_truth`: a body mask scored on the truth, as a picture.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable
from dataclasses import dataclass

import cv2
import numpy as np

from .optical_flow import CellGrid

BODY, BACKGROUND, IGNORED = 1, 0, -1


def cell_coverage(label_image: np.ndarray, labels: Iterable[int], grid: CellGrid) -> np.ndarray:
    """Fraction (0..1) of the pixels of each cell whose label is in ``labels`` (n_c)."""
    lab = np.asarray(label_image)
    if lab.ndim == 3 and lab.shape[2] == 1:
        lab = lab[:, :, 0]
    if lab.shape != (grid.height, grid.width):
        raise ValueError(f"label image is {lab.shape[::-1]} but the grid is over "
                         f"{grid.width}x{grid.height}")
    hit = np.isin(lab, np.asarray(list(labels), dtype=lab.dtype)).ravel()
    cell, pixels = _pixel_cells(grid)
    covered = np.bincount(cell[hit], minlength=grid.num_cells)
    return covered / pixels


@functools.lru_cache(maxsize=8)
def _pixel_cells(grid: CellGrid) -> tuple[np.ndarray, np.ndarray]:
    """Cell index of every pixel (flat, row-major) and the pixel count of every cell; cached,
    since it is the same for every frame of a camera."""
    rows = np.arange(grid.height) * grid.rows // grid.height
    cols = np.arange(grid.width) * grid.cols // grid.width
    cell = (rows[:, None] * grid.cols + cols[None, :]).ravel()
    cell.setflags(write=False)
    return cell, np.bincount(cell, minlength=grid.num_cells)


@dataclass
class CellTruth:
    """Per-cell ground truth accumulated frame by frame from label images."""

    grid: CellGrid
    body_labels: tuple[int, ...]
    distractor_labels: tuple[int, ...] = ()
    body_cover: float = 0.10

    def __post_init__(self):
        n = self.grid.num_cells
        self.max_body_cover = np.zeros(n)
        self.distractor_seen = np.zeros(n, bool)

    def update(self, label_image: np.ndarray) -> np.ndarray:
        """Add one frame; returns this frame's body coverage per cell."""
        cover = cell_coverage(label_image, self.body_labels, self.grid)
        self.max_body_cover = np.maximum(self.max_body_cover, cover)
        if self.distractor_labels:
            self.distractor_seen |= cell_coverage(
                label_image, self.distractor_labels, self.grid) > 0
        return cover

    def truth(self) -> np.ndarray:
        """BODY (1), BACKGROUND (0) or IGNORED (-1) per cell, over the episode so far."""
        t = np.full(self.grid.num_cells, IGNORED)
        t[self.max_body_cover >= self.body_cover] = BODY
        t[self.max_body_cover == 0] = BACKGROUND
        return t

    def distractor_cells(self) -> np.ndarray:
        """Background cells where the distractor appeared (bool, n_c)."""
        return self.distractor_seen & (self.truth() == BACKGROUND)


def mask_metrics(predicted: np.ndarray, truth: np.ndarray) -> dict:
    """Precision, recall and IoU of a boolean body mask on BODY/BACKGROUND/IGNORED truth.

    Ignored cells count neither way. With no predicted (or no true) body cell, precision (recall)
    is 1.0 by convention when there is nothing to get wrong, else 0.0.
    """
    pred = np.asarray(predicted, bool)
    truth = np.asarray(truth)
    if pred.shape != truth.shape:
        raise ValueError(f"mask {pred.shape} and truth {truth.shape} differ in shape")
    scored = truth != IGNORED
    tp = int(np.sum(pred & (truth == BODY)))
    fp = int(np.sum(pred & (truth == BACKGROUND)))
    fn = int(np.sum(~pred & (truth == BODY)))
    return {
        "true_positive": tp, "false_positive": fp, "false_negative": fn,
        "precision": tp / (tp + fp) if tp + fp else 1.0,
        "recall": tp / (tp + fn) if tp + fn else 1.0,
        "iou": tp / (tp + fp + fn) if tp + fp + fn else 1.0,
        "scored_cells": int(scored.sum()),
    }


def distractor_cells_marked(ever_marked: np.ndarray, distractor_cells: np.ndarray) -> int:
    """Number of distractor cells that were ever marked body."""
    return int(np.sum(np.asarray(ever_marked, bool) & np.asarray(distractor_cells, bool)))


def detection_latencies(times: np.ndarray, visible_motion: np.ndarray,
                        marked: np.ndarray) -> np.ndarray:
    """Per cell: first time marked body minus first time the robot's motion was visible in it.

    ``times`` (T), ``visible_motion`` and ``marked`` (T x n_c bool). Returns one latency (s) per
    cell that had visible motion and was detected after it; cells never detected are left out
    (they show in the recall). A cell marked before its first visible motion gives 0.
    """
    t = np.asarray(times, dtype=float)
    vis = np.asarray(visible_motion, bool)
    mk = np.asarray(marked, bool)
    if vis.shape != mk.shape or vis.shape[0] != t.shape[0]:
        raise ValueError(f"times {t.shape}, visible {vis.shape}, marked {mk.shape} disagree")
    out = []
    for j in range(vis.shape[1]):
        if vis[:, j].any() and mk[:, j].any():
            first_vis = t[np.argmax(vis[:, j])]
            first_mark = t[np.argmax(mk[:, j])]
            out.append(max(0.0, first_mark - first_vis))
    return np.asarray(out)


class EpisodeEvaluator:
    """Streams one episode, frame by frame, into the metrics of issue 4 (``metrics()``).

    Per frame: the label image, the scored body mask and the tracker's ``ṡ_j`` (and optionally
    named ``parts`` of the mask, scored separately for diagnosis). A cell's *visible motion*
    starts at the first frame where the robot covers at least ``body_cover`` of it and
    ``ṡ_j > 0``. Precision, recall and IoU are of the cells ever marked body against the
    episode's truth (:class:`CellTruth`), so a cell marked and later unmarked still counts.

    The accumulators have a fixed size (per cell: the largest body cover, distractor seen,
    first visible motion, first mark, ever marked per part), so the evaluator streams episodes
    of any length and round-trips through one flat vector (:meth:`to_vector`,
    :meth:`set_vector`) that a Drake system keeps as discrete state.
    """

    def __init__(self, grid: CellGrid, body_labels: Iterable[int],
                 distractor_labels: Iterable[int] = (), body_cover: float = 0.10,
                 parts: Iterable[str] = ()):
        self.truth = CellTruth(grid, tuple(body_labels), tuple(distractor_labels), body_cover)
        self.parts = tuple(parts)
        n = grid.num_cells
        self.frames = 0
        self.first_visible = np.full(n, np.inf)
        self.first_marked = np.full(n, np.inf)
        self.ever_marked = np.zeros(n, bool)
        self.ever_part = np.zeros((len(self.parts), n), bool)

    def vector_size(self) -> int:
        return 1 + (5 + len(self.parts)) * self.truth.grid.num_cells

    def to_vector(self) -> np.ndarray:
        """The accumulators as one flat vector (times never seen stored as -1)."""
        def times(x):
            return np.where(np.isfinite(x), x, -1.0)
        return np.concatenate([[self.frames], self.truth.max_body_cover,
                               self.truth.distractor_seen, times(self.first_visible),
                               times(self.first_marked), self.ever_marked,
                               self.ever_part.ravel()]).astype(float)

    def set_vector(self, vector: np.ndarray) -> None:
        """Restores the accumulators from :meth:`to_vector`'s output."""
        v = np.asarray(vector, dtype=float).ravel()
        if v.size != self.vector_size():
            raise ValueError(f"evaluator vector has {v.size} entries, expected "
                             f"{self.vector_size()}")
        n = self.truth.grid.num_cells
        self.frames = int(v[0])
        rows = v[1:].reshape(5 + len(self.parts), n)
        self.truth.max_body_cover = rows[0].copy()
        self.truth.distractor_seen = rows[1] > 0
        self.first_visible = np.where(rows[2] >= 0, rows[2], np.inf)
        self.first_marked = np.where(rows[3] >= 0, rows[3], np.inf)
        self.ever_marked = rows[4] > 0
        self.ever_part = rows[5:] > 0

    def update(self, time: float, label_image: np.ndarray, body_mask: np.ndarray,
               sdot: np.ndarray, parts: dict | None = None) -> None:
        n = self.truth.grid.num_cells
        body_mask = np.asarray(body_mask).ravel() > 0
        sdot = np.asarray(sdot, dtype=float).ravel()
        if body_mask.shape != (n,) or sdot.shape != (n,):
            raise ValueError(f"expected {n} cells, got mask {body_mask.shape}, sdot {sdot.shape}")
        parts = {} if parts is None else parts
        if set(parts) != set(self.parts):
            raise ValueError(f"expected mask parts {sorted(self.parts)}, got {sorted(parts)}")
        part_masks = [np.asarray(parts[name]).ravel() > 0 for name in self.parts]
        if any(m.shape != (n,) for m in part_masks):
            raise ValueError(f"expected {n} cells in every mask part")
        if not np.isfinite(time) or time < 0:
            raise ValueError(f"frame time must be finite and >= 0, got {time}")
        cover = self.truth.update(label_image)
        visible = (cover >= self.truth.body_cover) & (sdot > 0)
        self.first_visible = np.where(visible, np.minimum(self.first_visible, time),
                                      self.first_visible)
        self.first_marked = np.where(body_mask, np.minimum(self.first_marked, time),
                                     self.first_marked)
        self.ever_marked |= body_mask
        for k, mask in enumerate(part_masks):
            self.ever_part[k] |= mask
        self.frames += 1

    def latencies(self) -> np.ndarray:
        """Per cell with visible robot motion that was detected: first mark minus first visible
        motion (0 if marked before), as :func:`detection_latencies`."""
        both = np.isfinite(self.first_visible) & np.isfinite(self.first_marked)
        return np.maximum(0.0, self.first_marked[both] - self.first_visible[both])

    def _mask_summary(self, ever: np.ndarray) -> dict:
        out = mask_metrics(ever, self.truth.truth())
        out.update({
            "body_cells_marked": int(ever.sum()),
            "distractor_cells_marked": distractor_cells_marked(
                ever, self.truth.distractor_cells()),
        })
        return out

    def metrics(self) -> dict:
        if not self.frames:
            raise ValueError("no frames to evaluate")
        latencies = self.latencies()
        out = self._mask_summary(self.ever_marked)
        out.update({
            "frames": self.frames,
            "body_cells_true": int(np.sum(self.truth.truth() == BODY)),
            "distractor_cells": int(self.truth.distractor_cells().sum()),
            "latency_median_s": float(np.median(latencies)) if latencies.size else None,
            "latency_p90_s": float(np.percentile(latencies, 90)) if latencies.size else None,
            "latency_cells": int(latencies.size),
            # Every detected cell's latency, so that several episodes can be pooled.
            "latencies_s": [round(float(x), 4) for x in np.sort(latencies)],
        })
        if self.parts:
            out["parts"] = {name: self._mask_summary(self.ever_part[k])
                            for k, name in enumerate(self.parts)}
        return out


def draw_likelihood_map(image: np.ndarray, grid: CellGrid, eps: np.ndarray,
                        body: np.ndarray, sdot: np.ndarray | None = None) -> np.ndarray:
    """RGB uint8 picture: the camera image with body cells shaded red in proportion to
    Σ_i ε_ij (outlined), and cells with visual motion outlined blue (paper Figs. 3-5)."""
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[:, :, :3]
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    if img.shape[:2] != (grid.height, grid.width) or img.dtype != np.uint8:
        raise ValueError(f"image must be uint8 {grid.width}x{grid.height}, got {img.dtype} "
                         f"{img.shape}")
    out = img.astype(float)
    likelihood = np.asarray(eps, dtype=float).reshape(-1, grid.num_cells).sum(axis=0)
    body = np.asarray(body, bool).ravel()
    top = likelihood[body].max() if body.any() else 1.0
    red = np.array([255.0, 0.0, 0.0])
    for j in np.flatnonzero(body):
        u0, v0, u1, v1 = grid.cell_bounds(j)
        a = 0.3 + 0.4 * likelihood[j] / max(top, 1e-9)
        out[v0:v1, u0:u1] = (1 - a) * out[v0:v1, u0:u1] + a * red
    out = np.clip(out, 0, 255).astype(np.uint8)
    moving = np.zeros(grid.num_cells, bool) if sdot is None else np.asarray(sdot).ravel() > 0
    for j in range(grid.num_cells):
        if body[j] or moving[j]:
            u0, v0, u1, v1 = grid.cell_bounds(j)
            color = (255, 0, 0) if body[j] else (0, 0, 255)
            cv2.rectangle(out, (u0, v0), (u1 - 1, v1 - 1), color, 1)
    return out


def save_likelihood_png(path, image: np.ndarray, grid: CellGrid, eps: np.ndarray,
                        body: np.ndarray, sdot: np.ndarray | None = None) -> None:
    """Write :func:`draw_likelihood_map` to ``path`` as PNG."""
    save_png(path, draw_likelihood_map(image, grid, eps, body, sdot))


def save_png(path, rgb: np.ndarray) -> None:
    """Write an RGB uint8 picture to ``path`` as PNG."""
    with open(path, "wb") as f:
        f.write(png_bytes(rgb))


def png_bytes(rgb: np.ndarray) -> bytes:
    """An RGB uint8 picture encoded as PNG (to be written atomically by the caller)."""
    ok, data = cv2.imencode(".png", cv2.cvtColor(np.asarray(rgb), cv2.COLOR_RGB2BGR))
    if not ok:
        raise ValueError("could not encode the picture as PNG")
    return data.tobytes()


def draw_mask_vs_truth(image: np.ndarray, grid: CellGrid, marked: np.ndarray,
                       truth: np.ndarray, distractor: np.ndarray | None = None) -> np.ndarray:
    """RGB uint8 picture of a body mask scored on the truth: true positives shaded green,
    false positives red, missed body cells outlined yellow, distractor cells outlined blue."""
    out = draw_likelihood_map(image, grid, np.zeros(grid.num_cells),
                              np.zeros(grid.num_cells, bool)).astype(float)
    marked = np.asarray(marked, bool).ravel()
    truth = np.asarray(truth).ravel()
    for j, color in [(j, (0.0, 200.0, 0.0)) for j in np.flatnonzero(marked & (truth == BODY))] + [
            (j, (255.0, 0.0, 0.0)) for j in np.flatnonzero(marked & (truth == BACKGROUND))]:
        u0, v0, u1, v1 = grid.cell_bounds(j)
        out[v0:v1, u0:u1] = 0.5 * out[v0:v1, u0:u1] + 0.5 * np.array(color)
    out = np.clip(out, 0, 255).astype(np.uint8)
    outlines = [(j, (255, 255, 0)) for j in np.flatnonzero(~marked & (truth == BODY))]
    if distractor is not None:
        outlines += [(j, (0, 0, 255)) for j in np.flatnonzero(np.asarray(distractor, bool))]
    for j, color in outlines:
        u0, v0, u1, v1 = grid.cell_bounds(j)
        cv2.rectangle(out, (u0, v0), (u1 - 1, v1 - 1), color, 1)
    return out
