"""Simulated frames of a rig: several cameras fixed to one body, fired at the same instant.

The body has one attitude ``q_body`` (ICRS -> body, uniform on SO(3)); camera ``i`` mounted by
``q_mount_i`` (body -> camera) sees the sky at ``q_cam = q_mount_i * q_body``, i.e.
``v_cam = R_mount R_body v_icrs``. Each camera's frame is simulated by
:func:`service.core.sim.simulate_frame` with its own noise draws, so its truth (per-centroid
HIP, blends) is that camera's.

GF-7 (seed 001) carries two star cameras of 8.9 x 8.9 deg, 2048 x 2048 px. The paper gives no
angle between their optical axes and says the method does not depend on it; we take
``GF7_AXES_ANGLE_DEG`` = 70 deg, within the 60-90 deg usual for a pair of star-tracker heads
on one bracket (far enough apart that the Sun and the Earth rarely blind both, close enough to
share a thermally stable mount). Camera 0 ("1a") is the reference: its mounting is the
identity, so the body frame is its frame; camera 1's boresight is tilted from it by the angle
about the body x axis.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .attitude import quat_multiply, random_rotations
from .camera import Camera, Rig
from .sim import SimConfig, SimFrame, simulate_frame
from .types import Centroids

GF7_AXES_ANGLE_DEG = 70.0
"""Angle between the optical axes of GF-7's two star cameras, degrees (our choice: see above)."""

Quaternion = tuple[float, float, float, float]


def tilt_mounting(angle_deg: float, azimuth_deg: float = 0.0) -> Quaternion:
    """Mounting quaternion (body -> camera) of a camera whose boresight is tilted ``angle_deg``
    from the body +z axis (about +x, towards body +y), after a turn of ``azimuth_deg`` about +z
    (which moves the boresight's azimuth and the camera's roll with it)."""
    half = math.radians(angle_deg) / 2
    tilt = np.array([math.cos(half), math.sin(half), 0.0, 0.0])  # about body x
    half_az = math.radians(azimuth_deg) / 2
    spin = np.array([math.cos(half_az), 0.0, 0.0, math.sin(half_az)])  # about body z
    q = quat_multiply(tilt, spin)
    q = q / np.linalg.norm(q)
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def gf7_rig(angle_deg: float = GF7_AXES_ANGLE_DEG, camera: Camera | None = None) -> Rig:
    """GF-7's two cameras (seed 001: 8.9 x 8.9 deg, 2048 x 2048), axes ``angle_deg`` apart."""
    cam = camera if camera is not None else Camera.from_fov(8.9, 2048, 2048)
    return Rig((cam, cam), ((1.0, 0.0, 0.0, 0.0), tilt_mounting(angle_deg)))


@dataclass(frozen=True, slots=True)
class RigFrame:
    """One simulated rig frame: the body attitude and every camera's frame with its truth."""

    quaternion: np.ndarray  # (4,) ICRS -> body, [w, x, y, z]
    frames: tuple[SimFrame, ...]  # per camera; each quaternion is ICRS -> that camera

    def inputs(self, rig: Rig) -> list[tuple[Centroids, Camera, Quaternion]]:
        """The ``frames`` argument of :func:`service.core.pipeline.solve_rig`."""
        return [(f.centroids, cam, mount) for f, cam, mount in zip(self.frames, rig.cameras, rig.mountings,
                                                                      strict=True)]

    def to_record(self, frame_id: Any, rig: Rig, *,
                  camera_specs: Sequence[dict[str, Any]] | None = None) -> dict[str, Any]:
        """The recorded-frame JSON object of a rig (``cameras`` list; the truth lists every
        camera's HIPs one camera after the other, blends keyed by that running index)."""
        cams, hips, blends, offset = [], [], {}, 0
        for i, (f, cam, mount) in enumerate(zip(self.frames, rig.cameras, rig.mountings, strict=True)):
            spec = dict(camera_specs[i]) if camera_specs is not None else cam.to_spec()
            spec["mounting_quaternion"] = [float(v) for v in mount]
            rows = np.column_stack([f.centroids.xy, f.centroids.flux])
            cams.append({"camera": spec, "centroids": [[round(float(v), 4) for v in r] for r in rows]})
            hips += [None if h < 0 else int(h) for h in f.hip]
            blends.update({str(offset + k): list(v) for k, v in f.blends.items()})
            offset += len(f.hip)
        truth: dict[str, Any] = {"quaternion": [float(v) for v in self.quaternion], "hip": hips}
        if blends:
            truth["blends"] = blends
        return {"id": frame_id, "cameras": cams, "truth": truth}


def simulate_rig_frame(rig: Rig, quaternion: np.ndarray, config: SimConfig,
                       rng: np.random.Generator) -> RigFrame:
    """One frame of every camera of ``rig`` with the body at ``quaternion`` (ICRS -> body)."""
    q_body = np.asarray(quaternion, dtype=np.float64)
    frames = []
    for cam, mount in zip(rig.cameras, rig.mountings, strict=True):
        q_cam = quat_multiply(np.asarray(mount, dtype=np.float64), q_body)
        q_cam = q_cam / np.linalg.norm(q_cam)
        frames.append(simulate_frame(cam, q_cam, config, rng))
    return RigFrame(q_body, tuple(frames))


def simulate_rig_frames(rig: Rig, n: int, config: SimConfig, *,
                        rng: np.random.Generator | int | None = None) -> list[RigFrame]:
    """``n`` rig frames at body attitudes uniform on SO(3) (seeded by ``rng``)."""
    gen = np.random.default_rng(rng)
    return [simulate_rig_frame(rig, q, config, gen) for q in random_rotations(n, gen)]


def random_rig_points(
    rig: Rig, n_per_camera: Sequence[int], rng: np.random.Generator | int | None = None
) -> list[tuple[Centroids, Camera, Quaternion]]:
    """Uniformly random centroids in every camera (no real star): must never solve."""
    from .sim import random_points

    gen = np.random.default_rng(rng)
    return [(random_points(cam, k, gen), cam, mount)
            for cam, mount, k in zip(rig.cameras, rig.mountings, n_per_camera, strict=True)]
