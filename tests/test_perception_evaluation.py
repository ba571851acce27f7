"""Per-cell ground truth from label images, metrics, latencies, and the likelihood-map picture."""

import cv2
import numpy as np
import pytest

from sustain_drake.perception.evaluation import (
    BACKGROUND,
    BODY,
    IGNORED,
    CellTruth,
    cell_coverage,
    detection_latencies,
    distractor_cells_marked,
    draw_likelihood_map,
    mask_metrics,
    save_likelihood_png,
)
from sustain_drake.perception.optical_flow import CellGrid

GRID = CellGrid(80, 40, rows=2, cols=4)         # 20 x 20 px cells
ARM, TOOL, PERSON = 3, 4, 9


def labels():
    lab = np.zeros((40, 80, 1), np.int16)
    lab[0:20, 0:20] = ARM                          # cell 0 fully arm
    lab[0:5, 20:28] = TOOL                         # cell 1: 40 px of 400 = 10 % -> body
    lab[20:22, 40:42] = ARM                        # cell 6: 4 px = 1 % -> ignored
    lab[20:40, 60:80] = PERSON                     # cell 7: distractor only
    return lab


def test_coverage_and_truth_follow_the_ten_percent_rule():
    cover = cell_coverage(labels(), (ARM, TOOL), GRID)
    assert cover[[0, 1, 6]] == pytest.approx([1.0, 0.1, 0.01])
    truth = CellTruth(GRID, body_labels=(ARM, TOOL), distractor_labels=(PERSON,))
    truth.update(labels())
    t = truth.truth()
    assert t.tolist() == [BODY, BODY, BACKGROUND, BACKGROUND, BACKGROUND, BACKGROUND, IGNORED,
                          BACKGROUND]
    assert np.flatnonzero(truth.distractor_cells()).tolist() == [7]
    # over an episode: the arm later covers cell 2, so it is body from then on
    later = np.zeros((40, 80), np.int16)
    later[0:20, 40:60] = ARM
    truth.update(later)
    assert truth.truth()[2] == BODY and truth.truth()[0] == BODY
    with pytest.raises(ValueError, match="label image"):
        cell_coverage(np.zeros((10, 10)), (ARM,), GRID)


def test_metrics_ignore_the_ignored_cells():
    truth = np.array([BODY, BODY, BACKGROUND, BACKGROUND, IGNORED])
    m = mask_metrics(np.array([True, False, True, False, True]), truth)
    assert (m["precision"], m["recall"], m["iou"]) == (0.5, 0.5, pytest.approx(1 / 3))
    assert mask_metrics(np.zeros(5, bool), truth)["precision"] == 1.0
    assert distractor_cells_marked(np.array([1, 0, 1, 1, 0], bool),
                                   np.array([0, 0, 1, 0, 1], bool)) == 1
    with pytest.raises(ValueError, match="shape"):
        mask_metrics(np.zeros(3, bool), truth)


def test_latency_is_first_mark_minus_first_visible_motion():
    t = np.arange(6) * 0.5
    vis = np.zeros((6, 3), bool)
    mk = np.zeros((6, 3), bool)
    vis[1:, 0] = True
    mk[3:, 0] = True              # 1.0 s after visible motion
    vis[2:, 1] = True             # never detected: left out
    mk[0:, 2] = True              # marked but never visibly moving: left out
    assert detection_latencies(t, vis, mk).tolist() == [1.0]


def test_likelihood_picture_marks_body_red_and_motion_blue(tmp_path):
    image = np.full((40, 80, 4), 128, np.uint8)
    eps = np.zeros((2, 8))
    eps[0, 0] = 3
    body = np.zeros(8, bool)
    body[0] = True
    sdot = np.zeros(8)
    sdot[5] = 10.0
    rgb = draw_likelihood_map(image, GRID, eps, body, sdot)
    assert rgb.shape == (40, 80, 3)
    assert rgb[10, 10, 0] > 200 and rgb[10, 10, 2] < 100          # body cell shaded red
    assert tuple(rgb[20, 30]) == (0, 0, 255)                        # moving cell outlined blue
    assert tuple(rgb[10, 50]) == (128, 128, 128)                    # untouched
    path = tmp_path / "likelihood.png"
    save_likelihood_png(path, image, GRID, eps, body, sdot)
    back = cv2.imread(str(path))
    assert back.shape == (40, 80, 3) and back[10, 10, 2] > 200      # BGR on disk


def test_episode_evaluator_streams_frames_into_the_metrics():
    from sustain_drake.perception.evaluation import EpisodeEvaluator

    ev = EpisodeEvaluator(GRID, body_labels=(ARM, TOOL), distractor_labels=(PERSON,))
    lab = labels()
    sdot = np.zeros(8)
    for k in range(4):
        marked = np.zeros(8)
        if k == 0:
            sdot[0] = 5.0                       # the arm's cell moves visibly at t = 0
        if k >= 2:
            marked[[0, 7]] = 1                  # detected at t = 1.0, and the distractor too
        ev.update(0.5 * k, lab, marked, sdot)
    m = ev.metrics()
    assert m["frames"] == 4 and m["body_cells_true"] == 2 and m["body_cells_marked"] == 2
    assert m["precision"] == 0.5 and m["recall"] == 0.5
    assert m["distractor_cells"] == 1 and m["distractor_cells_marked"] == 1
    assert m["latency_median_s"] == 1.0 and m["latency_cells"] == 1
    assert m["latencies_s"] == [1.0]
    with pytest.raises(ValueError, match="expected 8 cells"):
        ev.update(3.0, lab, np.zeros(3), sdot)
    with pytest.raises(ValueError, match="no frames"):
        EpisodeEvaluator(GRID, (ARM,)).metrics()


def test_episode_evaluator_round_trips_its_vector_and_scores_parts():
    from sustain_drake.perception.evaluation import EpisodeEvaluator

    ev = EpisodeEvaluator(GRID, (ARM, TOOL), (PERSON,), parts=("cells", "features"))
    lab = labels()
    sdot = np.zeros(8)
    sdot[[0, 1]] = 3.0
    cells, features = np.zeros(8), np.zeros(8)
    cells[0] = 1
    features[[1, 7]] = 1
    ev.update(0.2, lab, np.maximum(cells, features), sdot,
              parts={"cells": cells, "features": features})
    copy = EpisodeEvaluator(GRID, (ARM, TOOL), (PERSON,), parts=("cells", "features"))
    copy.set_vector(ev.to_vector())
    assert np.array_equal(copy.to_vector(), ev.to_vector())
    m = copy.metrics()
    assert m == ev.metrics()
    assert m["parts"]["cells"]["precision"] == 1.0 and m["parts"]["cells"]["recall"] == 0.5
    assert m["parts"]["features"]["distractor_cells_marked"] == 1
    assert m["distractor_cells_marked"] == 1 and m["recall"] == 1.0
    assert m["latency_median_s"] == 0.0 and m["latency_cells"] == 2
    with pytest.raises(ValueError, match="mask parts"):
        ev.update(0.3, lab, cells, sdot)
    with pytest.raises(ValueError, match="entries"):
        copy.set_vector(np.zeros(3))


def test_mask_versus_truth_picture_colours_hits_errors_and_misses():
    from sustain_drake.perception.evaluation import draw_mask_vs_truth, png_bytes

    image = np.full((40, 80, 3), 128, np.uint8)
    truth = np.array([BODY, BODY, BACKGROUND, BACKGROUND, IGNORED, BACKGROUND, BACKGROUND,
                      BACKGROUND])
    marked = np.array([1, 0, 1, 0, 0, 0, 0, 0], bool)
    distractor = np.zeros(8, bool)
    distractor[7] = True
    rgb = draw_mask_vs_truth(image, GRID, marked, truth, distractor)
    assert rgb[10, 10, 1] > rgb[10, 10, 0]                        # true positive: green
    assert rgb[10, 50, 0] > rgb[10, 50, 1]                        # false positive: red
    assert tuple(rgb[0, 25]) == (255, 255, 0)                     # missed body: yellow outline
    assert tuple(rgb[20, 65]) == (0, 0, 255)                      # distractor: blue outline
    assert tuple(rgb[30, 30]) == (128, 128, 128)
    back = cv2.imdecode(np.frombuffer(png_bytes(rgb), np.uint8), cv2.IMREAD_COLOR)
    assert back.shape == (40, 80, 3) and back[10, 50, 2] > back[10, 50, 1]   # BGR on disk
