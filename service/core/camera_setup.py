"""What a one-camera frame's solve sets up before its search, kept per camera object.

Every frame of a camera asks the same things before ``auto``'s first pass: the search plan, the
camera's refusal, the compiled call's static arguments, the image's corner probes, the packed
camera rows. Each is cached already, but each cache is keyed by the camera's value, so a frame
paid five hashes of the camera dataclass and five lookups: ~5 us of a ~50-us clean frame, and
three times that when the processor's caches were cold (the benchmark alternates with tetra3rs;
``/work/s20/stamps_cold.py``). A :class:`CameraSetup` holds them all under one lookup by the
identity of the camera and options objects, as a caller that reuses them (the SDK, ``solve``
in a loop, ``bench_peers``) passes them, and then by their values, as the service and a replay
build both anew for every request (~20-30 us a frame of seed 001 where the general set-up's
value-keyed caches were asked one by one). With them in hand the first pass runs from the
centroids as given (:func:`~.first_pass.frame_first_pass_kernel`): a frame it proves builds no
observation. A camera seen for the first time gets its set-up before its first frame's search
(``pipeline._first_sight``, since session 24), so that frame takes the same path as the rest.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .camera import Camera
from .match import RigArrays
from .navdb.reader import NavDatabase, NavDatabaseSet

SETUPS_KEPT = 64
"""Camera setups kept per opened database (cleared when full)."""
SETUP_SIZES_KEPT = 512
"""Frame sizes whose packed rows a setup keeps (a frame of another size packs its own)."""


@dataclass(frozen=True, slots=True)
class CameraSetup:
    """One camera's set-up on one database for one method and options (see the module)."""

    camera: Camera
    options: Any
    method: str
    plan: list[tuple[NavDatabase, list[str]]]
    deepest: NavDatabase
    static: tuple[Any, ...]
    """:func:`~.first_pass.first_pass_kernel`'s arguments after the frame's own."""
    packed: Any
    """``static`` as one :class:`~.packed.Packed`, as :func:`~.first_pass.frame_first_pass_kernel`
    takes it."""
    probes: np.ndarray
    """The image's centre and corners, body frame (:func:`~.verify.camera_probes`)."""
    arrays: dict[int, RigArrays] = field(default_factory=dict)
    """The packed camera rows per frame size (:func:`~.match.rig_arrays`)."""
    chains: dict[Any, Any] = field(default_factory=dict)
    """The fallback chain's arguments per frame size (:func:`~.frame_chain.chain_setup`)."""
    entry: list[Any] = field(default_factory=lambda: [None])
    """``[e]``: :func:`~.first_pass.frame_first_pass_kernel`'s compiled entry for this set-up's
    argument types, once a call through the dispatcher has shown them (None until then, or where
    the kernel has several compiled signatures; :func:`~.first_pass.kernel_entry`)."""


def kept_setup(db: NavDatabase | NavDatabaseSet, camera: Camera, method: str, options: Any) -> CameraSetup | None:
    """The setup kept for these very objects, else for equal ones (a camera and options built
    anew for each request of the same camera, as the service and a replay build them), or None."""
    kept = db.__dict__.get("_camera_setups", _NONE)
    got = kept.last  # the last one found: a camera's frames in a row need no key built
    if got is not None and got.camera is camera and got.options is options and got.method == method:
        return got
    got = kept.get((id(camera), id(options), method))
    if got is not None and got.camera is camera and got.options is options:
        kept.last = got
        return got
    try:
        return db.__dict__.get("_camera_setups_by_value", _NONE).get((camera, options, method))
    except TypeError:  # options holding an unhashable value (an array given in-process)
        return None


def keep_setup(db: NavDatabase | NavDatabaseSet, setup: CameraSetup) -> None:
    """Keep ``setup`` on ``db``, found by the identity of its camera and options (it holds
    them, so their ids stay theirs) and by their values."""
    kept = db.__dict__.setdefault("_camera_setups", _Setups())
    by_value = db.__dict__.setdefault("_camera_setups_by_value", {})
    if len(kept) >= SETUPS_KEPT:
        kept.clear()
    if len(by_value) >= SETUPS_KEPT:
        by_value.clear()
    kept[(id(setup.camera), id(setup.options), setup.method)] = setup
    kept.last = setup
    try:
        by_value[(setup.camera, setup.options, setup.method)] = setup
    except TypeError:
        pass


class _Setups(dict[Any, CameraSetup]):
    """The set-ups kept by identity, and the last one found (``last``)."""

    __slots__ = ("last",)

    def __init__(self) -> None:
        super().__init__()
        self.last: CameraSetup | None = None


_NONE = _Setups()

__all__ = ["SETUPS_KEPT", "SETUP_SIZES_KEPT", "CameraSetup", "keep_setup", "kept_setup"]
