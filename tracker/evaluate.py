"""Accuracy of tracked joints against ground truth: MPJPE, PA-MPJPE, PCK and lost frames.

Inputs are the arrays of poses.npz and truth.npz (``tracker.io.poses.load_poses``).
Joints are matched by name (truth may hold a subset), frames by the ``frame``
arrays (by position when an array has none). With e_fj = |p_fj - g_fj| the
distance of tracked joint p from true joint g in frame f:

    lost frame     a truth frame missing from the poses, with status 2, or with a NaN matched joint
    MPJPE          mean of e_fj over the joints of frames not lost
    PA-MPJPE       the same after aligning each frame's tracked joints to the truth with the
                   similarity (s, R, t) minimising sum_j |s R p_j + t - g_j|^2 (Umeyama 1991)
    PCK            share of all truth joint-frames with e_fj < threshold; lost frames count as misses

Truth joints that are NaN (unknown) are left out of every mean and count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracker.errors import TrackerInputError
from tracker.status import LOST


@dataclass
class Report:
    """Overall and per-joint accuracy; lengths in millimetres, PCK as a share in [0, 1]."""

    mpjpe_mm: float
    pa_mpjpe_mm: float
    pck: float
    pck_threshold_mm: float
    lost_frames: int
    frames: int
    per_joint: dict[str, tuple[float, float]]  # joint name -> (MPJPE mm, PCK)
    far_share: float = float("nan")  # share of the frames scored with a joint further than FAR from its truth


FAR = 0.15
"""Metres: a frame with a joint further than this from its truth counts in :attr:`Report.far_share`."""


def evaluate(poses: dict[str, np.ndarray], truth: dict[str, np.ndarray], pck_threshold: float = 0.05) -> Report:
    """Compare tracked joints with the truth; ``pck_threshold`` in metres."""
    pose_names = list(poses["joint_names"])
    names = [name for name in truth["joint_names"] if name in pose_names]
    if not names:
        raise TrackerInputError(
            f"poses and truth share no joint name (poses: {', '.join(pose_names)}; "
            f"truth: {', '.join(truth['joint_names'])}); compare results of the same model"
        )
    truth_columns = [list(truth["joint_names"]).index(name) for name in names]
    pose_columns = [pose_names.index(name) for name in names]
    true = truth["joints"][:, truth_columns]  # (F, J, 3), F = truth frames
    frame_count = len(true)

    pose_rows = {int(frame): row for row, frame in enumerate(_frame_numbers(poses))}
    rows = np.array([pose_rows.get(int(frame), -1) for frame in _frame_numbers(truth)], dtype=np.int64)
    tracked = np.full_like(true, np.nan)
    found = rows >= 0
    tracked[found] = poses["joints"][rows[found]][:, pose_columns]
    lost = ~found | np.isnan(tracked).any(axis=(1, 2))
    if "status" in poses:
        lost[found] |= poses["status"][rows[found]] == LOST

    known = np.isfinite(true).all(axis=2)  # (F, J): truth joints to score
    scored = known & ~lost[:, None]
    error = np.where(scored, np.linalg.norm(tracked - true, axis=2), np.nan)
    hit = scored & (np.nan_to_num(error, nan=np.inf) < pck_threshold)
    aligned_error = np.where(scored, np.linalg.norm(_umeyama_align(tracked, true, scored) - true, axis=2), np.nan)

    per_joint = {name: (1000.0 * _mean(error[:, j]), _share(hit[:, j], known[:, j])) for j, name in enumerate(names)}
    far = np.asarray((np.nan_to_num(error, nan=0.0) > FAR).any(axis=1))
    return Report(
        mpjpe_mm=1000.0 * _mean(error),
        pa_mpjpe_mm=1000.0 * _mean(aligned_error),
        pck=_share(hit, known),
        pck_threshold_mm=1000.0 * pck_threshold,
        lost_frames=int(lost.sum()),
        frames=frame_count,
        per_joint=per_joint,
        far_share=_share(far, scored.any(axis=1)),
    )


def truth_within(truth: dict[str, np.ndarray], start: int, stop: int) -> dict[str, np.ndarray]:
    """The joints of ``truth`` (truth.npz arrays) in frames ``start``..``stop - 1`` only, with their frame numbers:
    what :func:`evaluate` scores a run of those frames against."""
    frames = _frame_numbers(truth)
    kept = (frames >= start) & (frames < stop)
    return {"joint_names": truth["joint_names"], "joints": truth["joints"][kept], "frame": frames[kept]}


def _frame_numbers(arrays: dict[str, np.ndarray]) -> np.ndarray:
    """The ``frame`` array, or 0..F-1 when there is none."""
    return arrays["frame"] if "frame" in arrays else np.arange(len(arrays["joints"]))


def _mean(values: np.ndarray) -> float:
    """Mean of the non-NaN values; NaN when there are none."""
    finite = values[~np.isnan(values)]
    return float(finite.mean()) if finite.size else float("nan")


def _share(hits: np.ndarray, total: np.ndarray) -> float:
    count = int(total.sum())
    return float(hits.sum()) / count if count else float("nan")


def _umeyama_align(source: np.ndarray, target: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Per frame, s R x + t for the similarity best mapping source (F, J, 3) onto target over weighted joints.

    With w the 0/1 weights (F, J), n = sum_j w_j, means mu_x, mu_y and centred
    points x_j, y_j: Sigma = sum_j w_j y_j x_j^T / n = U D V^T,
    S = diag(1, 1, sign(det U det V)), R = U S V^T,
    s = trace(D S) / (sum_j w_j |x_j|^2 / n), t = mu_y - s R mu_x.
    Frames with fewer than three weighted joints come back NaN.
    """
    w = weights.astype(np.float64)
    n = w.sum(axis=1)
    enough = n >= 3
    n_safe = np.where(enough, n, 1.0)
    x = np.where(weights[..., None], source, 0.0)
    y = np.where(weights[..., None], target, 0.0)
    mu_x = np.einsum("fj,fja->fa", w, x) / n_safe[:, None]
    mu_y = np.einsum("fj,fja->fa", w, y) / n_safe[:, None]
    xc, yc = x - mu_x[:, None], y - mu_y[:, None]
    sigma = np.einsum("fj,fja,fjb->fab", w, yc, xc) / n_safe[:, None, None]
    u, d, vt = np.linalg.svd(sigma)
    signs = np.ones_like(d)
    signs[:, 2] = np.sign(np.linalg.det(u) * np.linalg.det(vt))
    rotation = (u * signs[:, None, :]) @ vt
    variance = np.einsum("fj,fja,fja->f", w, xc, xc) / n_safe
    scale = np.where(variance > 0, (d * signs).sum(axis=1) / np.where(variance > 0, variance, 1.0), 0.0)
    aligned = scale[:, None, None] * np.einsum("fab,fjb->fja", rotation, xc) + mu_y[:, None]
    aligned[~enough] = np.nan
    return aligned


def format_report(report: Report) -> str:
    """The report as a small text table: overall numbers, then one line per joint."""
    threshold = f"PCK@{report.pck_threshold_mm:g}mm"
    lost_share = report.lost_frames / report.frames if report.frames else 0.0
    width = max([len("joint"), *map(len, report.per_joint)])
    lines = [
        f"frames {report.frames}, lost {report.lost_frames} ({100 * lost_share:.1f}%), "
        f"{100 * report.far_share:.1f}% of those scored with a joint beyond {1000 * FAR:g} mm",
        f"MPJPE {report.mpjpe_mm:.1f} mm   PA-MPJPE {report.pa_mpjpe_mm:.1f} mm   {threshold} {100 * report.pck:.1f}%",
        "",
        f"{'joint':<{width}}  {'MPJPE mm':>9}  {threshold:>11}",
    ]
    lines += [f"{name:<{width}}  {mpjpe:>9.1f}  {100 * pck:>10.1f}%" for name, (mpjpe, pck) in report.per_joint.items()]
    return "\n".join(lines)
