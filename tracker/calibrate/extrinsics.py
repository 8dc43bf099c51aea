"""Rig extrinsics from shared board views: board poses, pairwise camera poses, a spanning tree,
and a bundle adjustment.

Notation: T_ab = [[R_ab, t_ab], [0, 1]] maps frame b to frame a, X_a = R_ab X_b + t_ab; "r" is the
root camera (the first camera), "f" the board at frame f, "c" a camera.  In the code T_ab is a 4x4
array named ``a_from_b`` (``camera_from_board``, ``camera_from_root``, ``root_from_board``), as
everywhere in the package (tracker/__init__.py); OpenCV's (rvec, tvec) and the adjustment's
parameter vector are converted to and from it where they are met.

1. Board pose per view. With the camera's intrinsics the corners' pixels u_k are undistorted to
   ideal normalised coordinates x_k, and T_cf solves the planar PnP problem x_k ~ pi(R X_k + t)
   (IPPE, which returns both poses that fit a plane, the better one first, then Levenberg-
   Marquardt).
2. Pairwise poses. A frame f seen by cameras a and b gives one estimate of T_ab = T_af T_bf^-1:
   R_ab = R_af R_bf^T, t_ab = t_af - R_ab t_bf. Single estimates fail now and then (IPPE's mirror
   solution for a small or frontal board, a misread corner), so they are averaged robustly: the
   medoid rotation R_m (smallest sum of geodesic angles to the others) and the median translation
   t_m are found, estimates farther than max(1 deg, 3 x the median angle) from R_m or max(1 cm,
   3 x the median distance) from t_m are dropped, and the rest are averaged: the chordal L2 mean
   R = argmin_R sum ||R - R_i||_F^2, i.e. the projection of sum R_i onto SO(3) by SVD
   (U diag(1, 1, det UV^T) V^T), and the mean translation.
3. Chaining. Cameras are the nodes of a graph whose edges are the camera pairs with shared
   views, weighted by the number of shared frames. A maximum spanning tree from the root (Prim's
   algorithm) links every camera to the root through the best-supported pairs, and poses compose
   along it: T_cr = T_cp T_pr for a camera c with parent p. A camera not reached shares no view
   (directly or through others) with the root: an error.
4. Bundle adjustment. With every board pose T_rf (averaged over the cameras that see frame f as
   T_rc T_cf) the reprojection error

       E = sum_{c,f,k} rho( || u_cfk - K_c d_c( pi(R_cr (R_rf X_k + t_rf) + t_cr) ) ||^2 )

   is minimised over the camera poses T_cr (the root's held at identity: it fixes the gauge; the
   board's size fixes the scale), the board poses T_rf and, optionally, every camera's K and
   distortion (k3, and k2, held where the corners do not reach far enough from the image centre,
   as in intrinsics.py), by scipy.optimize.least_squares (trust-region reflective with LSMR steps solved
   tightly, Jacobian by finite differences on its known sparsity: a corner's residual depends on
   one camera and one board pose only). The first solve uses the Huber loss rho with a 1 px scale;
   observations whose error then exceeds max(3 px, 4 x the median) are dropped and plain least
   squares (rho(s) = s) finishes, again after each change of the inlier set (at most twice). Cameras
   whose distortion is not the 4-5 coefficient pinhole model (fixed intrinsics from a file: fisheye, rational, skew)
   are measured in ideal pixels instead: (fx x_n + cx, fy y_n + cy) of the undistorted corner.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix

from tracker.calibrate.board import Board, Detection
from tracker.calibrate.intrinsics import K2_REACH, K3_REACH, corner_reach
from tracker.camera import Camera
from tracker.geometry.se3 import exp_so3_many, from_rotation, inverse, log_so3, rotation_angle

_HUBER_SCALE = 1.0  # pixels
_OUTLIER_FLOOR = 3.0  # pixels


class SplitRigError(ValueError):
    """The rig's graph of shared views is split: ``unreached`` cameras share no view with the root."""

    def __init__(self, unreached: list[int]):
        super().__init__(f"split rig: cameras {unreached} are not linked to camera 0 by shared board views")
        self.unreached = unreached


@dataclass(frozen=True)
class PairEstimate:
    a_from_b: np.ndarray  # T_ab (4, 4): camera a from camera b
    shared: int  # frames both cameras see the board in
    kept: int  # estimates left after outlier rejection


@dataclass
class RigResult:
    cameras: list[Camera]  # their camera_from_world is camera_from_root
    root_from_board: dict[int, np.ndarray]  # (4, 4) per frame used
    rms: list[float]  # per camera, px, over the inlier observations, after the adjustment
    initial_rms: list[float]  # per camera, px, same observations, with the chained start poses
    frames: list[int]  # per camera: board views that entered the adjustment
    dropped: int = 0  # observations rejected as outliers


# ---------------------------------------------------------------------------------------------- #
# rotations


def chordal_mean(rotations: np.ndarray) -> np.ndarray:
    """argmin_R sum ||R - R_i||_F^2 over SO(3): the SVD projection of sum R_i."""
    u, _, vt = np.linalg.svd(np.sum(rotations, axis=0))
    return u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt


def robust_mean_pose(estimates: np.ndarray) -> tuple[np.ndarray, int]:
    """Robust average (see the module docstring) of estimates (n, 4, 4) of one transform a_from_b:
    the average a_from_b (4, 4) and the number of estimates kept."""
    estimates = np.asarray(estimates, dtype=np.float64).reshape(-1, 4, 4)
    rotations, translations = estimates[:, :3, :3], estimates[:, :3, 3]
    n = len(rotations)
    if n == 1:
        return from_rotation(rotations[0], translations[0]), 1
    probe = np.linspace(0, n - 1, min(n, 200)).round().astype(int)
    angles = rotation_angle(np.einsum("iba,jbc->ijac", rotations[probe], rotations[probe]))  # of R_i^T R_j
    medoid = rotations[probe[int(np.argmin(angles.sum(axis=1)))]]
    angle = rotation_angle(np.einsum("ba,ibc->iac", medoid, rotations))  # of R_m^T R_i
    centre = np.median(translations, axis=0)
    distance = np.linalg.norm(translations - centre, axis=1)
    keep = (angle <= max(np.radians(1.0), 3.0 * np.median(angle))) & (distance <= max(0.01, 3.0 * np.median(distance)))
    if not np.any(keep):
        keep = angle <= np.median(angle)
    return from_rotation(chordal_mean(rotations[keep]), translations[keep].mean(axis=0)), int(keep.sum())


# ---------------------------------------------------------------------------------------------- #
# steps 1-3


def board_pose(board: Board, detection: Detection, camera: Camera) -> np.ndarray | None:
    """T_cf, camera_from_board (4, 4) of one view (planar PnP on undistorted corners); None when
    PnP fails or puts the board behind the camera."""
    objects = board.object_points[detection.ids]
    normalised = camera.undistort_pixels(detection.pixels).reshape(-1, 1, 2)
    try:
        count, rvecs, tvecs, _ = cv2.solvePnPGeneric(objects, normalised, np.eye(3), None, flags=cv2.SOLVEPNP_IPPE)
    except cv2.error:
        return None
    if not count:
        return None
    r, t = cv2.solvePnPRefineLM(objects, normalised, np.eye(3), None, rvecs[0].copy(), tvecs[0].copy())
    if t[2, 0] <= 0:
        return None
    return from_rotation(cv2.Rodrigues(r)[0], t.ravel())


def pairwise_poses(camera_from_board: list[dict[int, np.ndarray]]) -> dict[tuple[int, int], PairEstimate]:
    """T_ab for every camera pair a < b that sees the board in at least one common frame, from each
    camera's camera_from_board (4, 4) per frame: T_ab = T_af T_bf^-1."""
    pairs = {}
    for a in range(len(camera_from_board)):
        for b in range(a + 1, len(camera_from_board)):
            shared = sorted(set(camera_from_board[a]) & set(camera_from_board[b]))
            if not shared:
                continue
            estimates = [camera_from_board[a][f] @ inverse(camera_from_board[b][f]) for f in shared]
            a_from_b, kept = robust_mean_pose(np.array(estimates))
            pairs[(a, b)] = PairEstimate(a_from_b, len(shared), kept)
    return pairs


def spanning_tree(pairs: dict[tuple[int, int], PairEstimate], root: int = 0) -> dict[int, int]:
    """Parent of every camera reached from ``root`` in the maximum spanning tree of shared views
    (Prim's algorithm); cameras not reached are missing from the result, the root maps to itself."""
    parent = {root: root}
    while True:
        best = None
        for (a, b), pair in pairs.items():
            for inside, outside in ((a, b), (b, a)):
                if inside in parent and outside not in parent:
                    key = (pair.kept, pair.shared, -outside)
                    if best is None or key > best[0]:
                        best = (key, inside, outside)
        if best is None:
            return parent
        parent[best[2]] = best[1]


def chain_poses(
    parent: dict[int, int], pairs: dict[tuple[int, int], PairEstimate], root: int = 0
) -> dict[int, np.ndarray]:
    """T_cr, camera_from_root (4, 4), of every camera in the tree, composed along it: T_cr = T_cp T_pr."""
    result = {root: np.eye(4)}

    def solve(c: int) -> np.ndarray:
        if c not in result:
            p = parent[c]
            c_from_p = pairs[(c, p)].a_from_b if (c, p) in pairs else inverse(pairs[(p, c)].a_from_b)
            result[c] = c_from_p @ solve(p)
        return result[c]

    for c in parent:
        solve(c)
    return result


# ---------------------------------------------------------------------------------------------- #
# step 4


def _exact_model(camera: Camera) -> bool:
    return not camera.fisheye and len(camera.distortions) in (4, 5) and camera.matrix[0, 1] == 0.0


def _intrinsic_vector(camera: Camera) -> np.ndarray:
    K = camera.matrix
    distortions = np.zeros(5)
    if _exact_model(camera):
        distortions[: len(camera.distortions)] = camera.distortions
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *distortions])


def project(intrinsics: np.ndarray, points_camera: np.ndarray) -> np.ndarray:
    """Pixels (m, 2) of camera-frame points (m, 3) with per-point intrinsics (m, 9):
    fx fy cx cy k1 k2 p1 p2 k3, OpenCV's pinhole model (tracker/camera.py)."""
    x = points_camera[:, 0] / points_camera[:, 2]
    y = points_camera[:, 1] / points_camera[:, 2]
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = intrinsics.T
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([fx * xd + cx, fy * yd + cy], axis=1)


def _rotvec_translation(a_from_b: np.ndarray) -> np.ndarray:
    """(log_so3(R), t) (6,) of a transform: the adjustment's parameters of one pose."""
    return np.concatenate([log_so3(np.ascontiguousarray(a_from_b[:3, :3], dtype=np.float64)), a_from_b[:3, 3]])


class _Problem:
    """The bundle adjustment's observations, parameter layout and residual function."""

    def __init__(
        self,
        board: Board,
        cameras: list[Camera],
        views: list[dict[int, Detection]],
        frames: list[int],
        refine_intrinsics: bool,
        root: int,
    ):
        self.count = len(cameras)
        self.root = root
        self.frames = frames
        self.refine = refine_intrinsics
        slot = {f: i for i, f in enumerate(frames)}
        cam, frame, objects, targets = [], [], [], []
        for c, (camera, detections) in enumerate(zip(cameras, views)):
            exact = refine_intrinsics or _exact_model(camera)
            for f, detection in detections.items():
                if f not in slot:
                    continue
                pixels = detection.pixels
                if not exact:  # ideal pixels of the undistorted corners
                    xn = camera.undistort_pixels(pixels)
                    K = camera.matrix
                    pixels = np.stack([K[0, 0] * xn[:, 0] + K[0, 2], K[1, 1] * xn[:, 1] + K[1, 2]], axis=1)
                cam.append(np.full(len(pixels), c))
                frame.append(np.full(len(pixels), slot[f]))
                objects.append(board.object_points[detection.ids])
                targets.append(pixels)
        self.cam = np.concatenate(cam)
        self.frame = np.concatenate(frame)
        self.objects = np.concatenate(objects)
        self.targets = np.concatenate(targets)
        self.intrinsics = np.array([_intrinsic_vector(camera) for camera in cameras])
        self.free = [c for c in range(self.count) if c != root]
        self.n_cam = 6 * len(self.free)
        self.n_frame = 6 * len(frames)
        self.n_intr = 9 * self.count if refine_intrinsics else 0
        self.held = np.zeros((self.count, 9), dtype=bool)
        for c, detections in enumerate(views):
            if refine_intrinsics and detections:
                reach = corner_reach(list(detections.values()), cameras[c].size)
                self.held[c, 8] = reach < K3_REACH  # k3, as in intrinsics.py
                self.held[c, 5] = reach < K2_REACH  # k2

    def pack(self, camera_from_root: dict[int, np.ndarray], root_from_board: dict[int, np.ndarray]) -> np.ndarray:
        """The parameter vector: per free camera, then per board frame, (rotation vector, translation)."""
        cams = [_rotvec_translation(camera_from_root[c]) for c in self.free]
        boards = [_rotvec_translation(root_from_board[f]) for f in self.frames]
        parts = cams + boards + ([self.intrinsics.ravel()] if self.refine else [])
        return np.concatenate(parts) if parts else np.zeros(0)

    def unpack(self, x: np.ndarray):
        cam_r = np.zeros((self.count, 3))
        cam_t = np.zeros((self.count, 3))
        free = x[: self.n_cam].reshape(-1, 6)
        cam_r[self.free], cam_t[self.free] = free[:, :3], free[:, 3:]
        boards = x[self.n_cam : self.n_cam + self.n_frame].reshape(-1, 6)
        intrinsics = x[self.n_cam + self.n_frame :].reshape(-1, 9) if self.refine else self.intrinsics
        board_r = np.ascontiguousarray(boards[:, :3], dtype=np.float64)  # for se3's njit functions
        return cam_r, cam_t, board_r, boards[:, 3:], intrinsics

    def residuals(self, x: np.ndarray, select: np.ndarray | None = None) -> np.ndarray:
        cam_r, cam_t, board_r, board_t, intrinsics = self.unpack(x)
        cam, frame, objects, targets = self.cam, self.frame, self.objects, self.targets
        if select is not None:
            cam, frame, objects, targets = cam[select], frame[select], objects[select], targets[select]
        Rc, Rf = exp_so3_many(cam_r), exp_so3_many(board_r)
        in_root = np.einsum("mij,mj->mi", Rf[frame], objects) + board_t[frame]
        in_camera = np.einsum("mij,mj->mi", Rc[cam], in_root) + cam_t[cam]
        return project(intrinsics[cam], in_camera) - targets

    def sparsity(self, select: np.ndarray) -> csr_matrix:
        """Which parameters each residual depends on: its camera's pose (unless the root), its
        board pose and, when refined, its camera's intrinsics."""
        cam, frame = self.cam[select], self.frame[select]
        rows_of_obs = np.arange(2 * len(cam)).reshape(-1, 2)  # (m, 2): the x and y rows of each observation
        column = np.full(self.count, -1)
        column[self.free] = np.arange(len(self.free))
        blocks = []
        has = column[cam] >= 0
        blocks.append((rows_of_obs[has], 6 * column[cam[has]], 6))
        blocks.append((rows_of_obs, self.n_cam + 6 * frame, 6))
        if self.refine:
            blocks.append((rows_of_obs, self.n_cam + self.n_frame + 9 * cam, 9))
        row_parts, col_parts = [], []
        for obs_rows, start, width in blocks:
            r = np.repeat(obs_rows, width, axis=1)  # (m, 2 width)
            c = np.tile(start[:, None] + np.arange(width), (1, 2))
            row_parts.append(r.ravel())
            col_parts.append(c.ravel())
        rows, cols = np.concatenate(row_parts), np.concatenate(col_parts)
        if self.refine:  # held intrinsics (see calibrate_rig) get no Jacobian column and so stay put
            held = np.flatnonzero(self.held.ravel()) + self.n_cam + self.n_frame
            keep = ~np.isin(cols, held)
            rows, cols = rows[keep], cols[keep]
        shape = (2 * len(cam), self.n_cam + self.n_frame + self.n_intr)
        return csr_matrix((np.ones(len(rows), dtype=np.int8), (rows, cols)), shape=shape)


def per_camera_rms(errors: np.ndarray, cam: np.ndarray, count: int) -> list[float]:
    """RMS of the point errors |e| per camera (NaN for a camera without observations)."""
    return [float(np.sqrt(np.mean(errors[cam == c] ** 2))) if np.any(cam == c) else float("nan") for c in range(count)]


def calibrate_rig(
    board: Board,
    cameras: list[Camera],
    views: list[dict[int, Detection]],
    *,
    refine_intrinsics: bool = False,
    keep_frames: tuple[int, ...] = (),
    max_frames: int = 300,
) -> RigResult:
    """Extrinsics of cameras (their intrinsics given) from board detections per camera, steps 1-4.

    ``views[c]`` maps frame index -> Detection for camera c. Frames seen by two or more cameras
    enter the adjustment (at most ``max_frames`` of them, evenly spread), and frames seen by one
    camera too when intrinsics are refined; ``keep_frames`` always enter. Raises SplitRigError (its
    ``unreached``: the cameras' indices) when the rig's graph of shared views is split.
    """
    count = len(cameras)
    camera_from_board: list[dict[int, np.ndarray]] = []
    for camera, detections in zip(cameras, views):
        found = {}
        for f, detection in detections.items():
            pose = board_pose(board, detection, camera)
            if pose is not None:
                found[f] = pose
        camera_from_board.append(found)
    pairs = pairwise_poses(camera_from_board)
    parent = spanning_tree(pairs)  # the root is camera 0
    if len(parent) < count:
        raise SplitRigError(sorted(set(range(count)) - set(parent)))
    camera_from_root = chain_poses(parent, pairs)

    seen: dict[int, list[int]] = {}
    for c, found in enumerate(camera_from_board):
        for f in found:
            seen.setdefault(f, []).append(c)
    shared = sorted(f for f, cams in seen.items() if len(cams) > 1)
    if len(shared) > max_frames:
        shared = [shared[i] for i in np.linspace(0, len(shared) - 1, max_frames).round().astype(int)]
    chosen = set(shared) | {f for f in keep_frames if f in seen}
    if refine_intrinsics or count == 1:
        chosen |= set(seen)
    frames = sorted(chosen)

    root_from_board = {}
    for f in frames:
        estimates = [inverse(camera_from_root[c]) @ camera_from_board[c][f] for c in seen[f]]
        root_from_board[f], _ = robust_mean_pose(np.array(estimates))

    problem = _Problem(
        board,
        cameras,
        [{f: d for f, d in v.items() if f in camera_from_board[c]} for c, v in enumerate(views)],
        frames,
        refine_intrinsics,
        root=0,
    )
    x = problem.pack(camera_from_root, root_from_board)
    select = np.ones(len(problem.cam), dtype=bool)
    initial = np.linalg.norm(problem.residuals(x), axis=1)
    for round_ in range(3):
        # Huber first (robust to misread corners), plain least squares once the outliers are out
        result = least_squares(
            lambda v, s=select: problem.residuals(v, s).ravel(),
            x,
            jac_sparsity=problem.sparsity(select),
            method="trf",
            loss="huber" if round_ == 0 else "linear",
            f_scale=_HUBER_SCALE,
            x_scale="jac",
            ftol=1e-9,
            xtol=1e-9,
            gtol=1e-9,
            max_nfev=100,
            tr_options={"atol": 1e-12, "btol": 1e-12},
        )
        x = result.x
        errors = np.linalg.norm(problem.residuals(x), axis=1)
        inliers = errors <= max(_OUTLIER_FLOOR, 4.0 * float(np.median(errors[select])))
        if round_ > 0 and np.array_equal(inliers, select):
            break
        select = inliers

    cam_r, cam_t, board_r, board_t, intrinsics = problem.unpack(x)
    rotations = exp_so3_many(cam_r)
    out = []
    for c, camera in enumerate(cameras):
        matrix, distortions = camera.matrix, camera.distortions
        if refine_intrinsics:
            fx, fy, cx, cy = intrinsics[c, :4]
            matrix = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
            distortions = intrinsics[c, 4:]
        out.append(replace(camera, matrix=matrix, distortions=distortions, rotation=rotations[c], translation=cam_t[c]))
    board_rot = exp_so3_many(board_r)
    used = set(frames)
    return RigResult(
        cameras=out,
        root_from_board={f: from_rotation(board_rot[i], board_t[i]) for i, f in enumerate(frames)},
        rms=per_camera_rms(errors[select], problem.cam[select], count),
        initial_rms=per_camera_rms(initial[select], problem.cam[select], count),
        frames=[len(used.intersection(camera_from_board[c])) for c in range(count)],
        dropped=int((~select).sum()),
    )


# ---------------------------------------------------------------------------------------------- #
# world frames

FLOOR_FROM_BOARD = np.diag([1.0, -1.0, -1.0, 1.0])  # board face up on the floor: z up
FLOOR_FROM_BOARD.setflags(write=False)


def to_world(cameras: list[Camera], world_from_root: np.ndarray) -> list[Camera]:
    """Cameras re-expressed in a new world frame: T_cw = T_cr T_rw (their camera_from_world is
    camera_from_root on the way in)."""
    root_from_world = inverse(world_from_root)
    return [camera.with_camera_from_world(camera.camera_from_world @ root_from_world) for camera in cameras]
