"""Opaque boxes standing in a rendered scene, such as a table in front of the legs: ray casting and shading.

A box is its world_from_box transform (4x4) and half extents h (3,). The ray of normalised image
coordinates (x, y) leaves the camera centre o along d = R^T (x, y, 1), so the ray parameter t is the
depth z in the camera. It meets the box where the three axes' slab intervals overlap (Kay & Kajiya 1986):

    t_a- , t_a+ = (-h_a - o'_a) / d'_a , (h_a - o'_a) / d'_a      o', d' in the box frame
    t_near = max_a min(t_a-, t_a+),  t_far = min_a max(t_a-, t_a+)

a hit when t_near <= t_far and t_near > 0 (cameras stand outside boxes), at depth t_near on the face
of the axis attaining it. Faces are shaded like the body's surfaces: ambient + key max(0, n.l) + fill |n.v|.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracker.camera import Camera

TABLE_ALBEDO = (0.22, 0.38, 0.52)
"""BGR reflectance of a table: mid-brown wood."""


@dataclass(frozen=True)
class Box:
    """A box: ``world_from_box`` (4, 4), ``half`` extents (3,) metres along its axes, BGR ``albedo`` in [0, 1]."""

    world_from_box: np.ndarray
    half: np.ndarray
    albedo: tuple[float, float, float] = TABLE_ALBEDO


def box_corners(box: Box) -> np.ndarray:
    """The eight corners (8, 3) of ``box`` in world."""
    signs = np.array(np.meshgrid([-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0], indexing="ij")).reshape(3, -1).T
    return (signs * box.half) @ box.world_from_box[0:3, 0:3].T + box.world_from_box[0:3, 3]


def cast_boxes(boxes: list[Box], camera: Camera, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest box hit along the rays of normalised coordinates ``xy`` (M, 2): depth z (M,) (inf: none),
    the box's index (M,) (-1: none) and the unit face normal (M, 3) in the camera frame, towards the camera."""
    xy = np.asarray(xy, dtype=np.float64)
    depth = np.full(len(xy), np.inf)
    index = np.full(len(xy), -1, dtype=np.int64)
    normal = np.zeros((len(xy), 3))
    rays = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)  # camera frame, z = 1
    for k, box in enumerate(boxes):
        camera_from_box = camera.camera_from_world @ box.world_from_box
        box_from_camera = np.linalg.inv(camera_from_box)
        origin = box_from_camera[0:3, 3]
        direction = rays @ box_from_camera[0:3, 0:3].T
        with np.errstate(divide="ignore", invalid="ignore"):
            low = (-box.half - origin) / direction
            high = (box.half - origin) / direction
        near_each = np.where(np.isnan(low), -np.inf, np.minimum(low, high))  # a ray parallel to a slab
        far_each = np.where(np.isnan(high), np.inf, np.maximum(low, high))
        near = np.maximum(np.maximum(near_each[:, 0], near_each[:, 1]), near_each[:, 2])  # by columns: a reduction
        far = np.minimum(np.minimum(far_each[:, 0], far_each[:, 1]), far_each[:, 2])  # along 3 is slow in numpy
        hit = (near <= far) & (near > 0.0) & (near < depth)
        rows = np.flatnonzero(hit)
        axis = np.where(near_each[rows, 1] > near_each[rows, 0], 1, 0)  # the first axis attaining the max
        axis = np.where(near_each[rows, 2] > near_each[rows, axis], 2, axis)
        towards = -np.sign(direction[rows, axis])  # the face's normal in the box frame is +-1 along that axis
        depth[rows], index[rows] = near[rows], k
        normal[rows] = towards[:, None] * camera_from_box[0:3, 0:3].T[axis]
    return depth, index, normal


def backdrop(
    boxes: list[Box],
    camera: Camera,
    rays: np.ndarray,
    *,
    background: np.ndarray,
    light_world: np.ndarray,
    ambient: float,
    key: float,
    fill: float,
    blur: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The background (H, W, 3) uint8 with the boxes drawn over it, and their depth (H, W) (inf where none).

    ``rays`` (H, W, 2) normalised coordinates of the pixel centres; ``light_world`` the unit direction
    towards the key light; the boxes' coverage is softened by a Gaussian of ``blur`` px like the body's.
    """
    h, w = rays.shape[:2]
    depth, index, normal = cast_boxes(boxes, camera, rays.reshape(-1, 2))
    view = np.concatenate([rays.reshape(-1, 2), np.ones((h * w, 1))], axis=1)
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    light = camera.rotation @ light_world
    shade = ambient + key * np.maximum(normal @ light, 0.0) + fill * np.abs(np.sum(normal * view, axis=1))
    albedo = np.array([box.albedo for box in boxes] + [(0.0, 0.0, 0.0)], dtype=np.float64)  # -1: none
    mask: np.ndarray = (index >= 0).astype(np.float32).reshape(h, w)
    colour: np.ndarray = (255.0 * albedo[index] * (shade * (index >= 0))[:, None]).astype(np.float32).reshape(h, w, 3)
    if blur > 0:
        colour = cv2.GaussianBlur(colour, (0, 0), blur, borderType=cv2.BORDER_REPLICATE)
        mask = cv2.GaussianBlur(mask, (0, 0), blur, borderType=cv2.BORDER_REPLICATE)
    image = colour + (1.0 - mask)[..., None] * background.astype(np.float32)
    return np.clip(image + 0.5, 0.0, 255.0).astype(np.uint8), depth.reshape(h, w)
