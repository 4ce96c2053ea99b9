"""Model editing shared by the dm_control-based tasks: load, edit, recompile, swap, render.

Geometry contexts (lengths, sizes) change masses, inertias and bounding volumes, so a new value is
applied by editing an `mujoco.MjSpec` and recompiling, never by writing `geom_size` in place
(google-deepmind/mujoco#609, #1080). Compiling the suite XML costs ~80 ms, almost all of it for
the procedural skybox/grid textures, which do not affect physics. The physics models are therefore
compiled from a spec whose textures are shrunk to 2x2 (~1 ms), and frames are rendered with one
fully textured copy whose visual geometry is synchronised from the model in force.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass
import importlib.util
from pathlib import Path
import warnings

import mujoco
import numpy as np

__all__ = [
    'CompiledModel',
    'ModelCache',
    'SyncedRenderer',
    'compile_spec',
    'copy_physical_state',
    'load_model_spec',
    'load_suite_spec',
    'suite_dir',
]

_COMMON_ASSETS = ('materials.xml', 'skybox.xml', 'visual.xml')
_TINY_TEXTURE = 2
_SETTOTALMASS_DEPRECATED = r"compiler attribute 'settotalmass' is deprecated"
"""The start of MuJoCo's warning on compiling a model that sets settotalmass (mujoco 3.17)."""


def suite_dir() -> Path:
    """Directory of the dm_control suite XML files, found without importing dm_control.suite."""
    spec = importlib.util.find_spec('dm_control')
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError('dm_control is not installed: pip install dm-control (matching mujoco)')
    return Path(next(iter(spec.submodule_search_locations))) / 'suite'


def load_suite_spec(xml_name: str, *, light_textures: bool) -> mujoco.MjSpec:
    """Parse a suite model (e.g. 'cheetah.xml') with its common assets into an editable spec.

    With `light_textures` every texture is shrunk to 2x2 pixels: same model layout, ~100x faster
    compile, wrong colours (only for models that are never rendered).
    """
    root = suite_dir()
    path = root / xml_name
    if not path.is_file():
        raise FileNotFoundError(f'dm_control suite model {path} not found')
    assets = {f'./common/{name}': (root / 'common' / name).read_bytes() for name in _COMMON_ASSETS}
    spec = mujoco.MjSpec.from_string(path.read_text(), assets)
    return _lighten(spec) if light_textures else spec


def compile_spec(spec: mujoco.MjSpec, *, suite: bool) -> mujoco.MjModel:
    """Compile a spec; for a dm_control suite model, without MuJoCo's settotalmass warning.

    The suite's cheetah.xml declares `<compiler settotalmass="14"/>`, which MuJoCo now warns
    about as deprecated on every compile: every `suite:cheetah.xml` task file printed it, and the
    user cannot act on it (it is dm_control's file). The replacement MuJoCo suggests
    (mj_setTotalmass + mj_setConst after compiling) gives the same masses but not the compiler's
    `stat.meanmass` / `stat.meaninertia` (the solver's scale), so the suite's model is compiled
    as dm_control compiles it and exactly that warning is silenced. A user's own MJCF
    (`suite=False`) keeps the warning: there it can be fixed. The built-in cheetah families set
    a density instead (sim_bridge/cheetah.py) and never reach the filter.
    """
    if not suite or spec.compiler.settotalmass <= 0:
        return spec.compile()
    with warnings.catch_warnings():
        warnings.filterwarnings('ignore', message=_SETTOTALMASS_DEPRECATED, category=UserWarning)
        return spec.compile()


def load_model_spec(path: Path, *, light_textures: bool) -> mujoco.MjSpec:
    """Parse a user's MJCF file (includes and assets relative to it) into an editable spec."""
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except (ValueError, RuntimeError) as error:  # mujoco's parse errors name line and element
        raise ValueError(f'model {path}: {error}') from None
    return _lighten(spec) if light_textures else spec


def _lighten(spec: mujoco.MjSpec) -> mujoco.MjSpec:
    """Shrink every texture to 2x2: same physics, ~100x faster compile, never rendered."""
    for texture in spec.textures:
        texture.width = _TINY_TEXTURE
        texture.height = _TINY_TEXTURE
    return spec


@dataclass
class CompiledModel:
    """A compiled model with its own data buffer, reused whenever its context comes back."""

    model: mujoco.MjModel
    data: mujoco.MjData


class ModelCache:
    """Small LRU of compiled models keyed by the geometry-relevant part of the context."""

    def __init__(self, build: Callable[[Hashable], mujoco.MjModel], capacity: int = 16) -> None:
        if capacity < 1:
            raise ValueError(f'ModelCache capacity must be >= 1, got {capacity}')
        self._build = build
        self._capacity = capacity
        self._entries: OrderedDict[Hashable, CompiledModel] = OrderedDict()
        self.compiles = 0
        """How many times a model was compiled (cache misses), for tests and benchmarks."""

    def get(self, key: Hashable) -> CompiledModel:
        """The compiled model for `key`, compiling it on a miss and evicting the oldest entry."""
        entry = self._entries.get(key)
        if entry is not None:
            self._entries.move_to_end(key)
            return entry
        model = self._build(key)
        self.compiles += 1
        entry = CompiledModel(model=model, data=mujoco.MjData(model))
        self._entries[key] = entry
        if len(self._entries) > self._capacity:
            self._entries.popitem(last=False)
        return entry

    def __len__(self) -> int:
        return len(self._entries)


def copy_physical_state(
    src_model: mujoco.MjModel,
    src: mujoco.MjData,
    dst_model: mujoco.MjModel,
    dst: mujoco.MjData,
) -> None:
    """Carry positions, velocities, activations, controls and time into another model's data.

    Both models must share the kinematic layout (nq, nv, na, nu); derived quantities are
    recomputed with `mj_forward` under the destination model.
    """
    for attr in ('nq', 'nv', 'na', 'nu'):
        if getattr(src_model, attr) != getattr(dst_model, attr):
            raise ValueError(
                f'cannot carry state across models with different {attr}: '
                f'{getattr(src_model, attr)} != {getattr(dst_model, attr)}'
            )
    dst.time = src.time
    dst.qpos[:] = src.qpos
    dst.qvel[:] = src.qvel
    dst.act[:] = src.act
    dst.ctrl[:] = src.ctrl
    dst.qacc_warmstart[:] = src.qacc_warmstart
    mujoco.mj_forward(dst_model, dst)


# Model fields read by mjv_updateScene that depend on the context (geometry, camera/light
# placement relative to the centre of mass); everything else (materials, textures) is shared.
_VISUAL_FIELDS = (
    'geom_size', 'geom_rbound', 'geom_aabb', 'geom_pos', 'geom_quat', 'geom_rgba',
    'site_size', 'site_pos', 'site_rgba', 'body_pos', 'body_mass', 'body_subtreemass',
    'cam_pos', 'cam_quat', 'cam_poscom0', 'cam_pos0', 'cam_mat0',
    'light_pos', 'light_dir', 'light_poscom0', 'light_pos0', 'light_dir0',
)


class SyncedRenderer:
    """Offscreen RGB renderer over a textured model whose geometry follows the model in force."""

    def __init__(self, textured: mujoco.MjModel, camera: int | str) -> None:
        self._model = textured
        self._camera = camera
        self._renderer: mujoco.Renderer | None = None
        self._size: tuple[int, int] | None = None

    def render(
        self, model: mujoco.MjModel, data: mujoco.MjData, height: int, width: int
    ) -> np.ndarray:
        """Render `data` (simulated under `model`) from the tracking camera as uint8 HxWx3."""
        if height < 1 or width < 1:
            raise ValueError(f'render size must be positive, got {height}x{width}')
        for name in _VISUAL_FIELDS:
            getattr(self._model, name)[:] = getattr(model, name)
        self._model.stat.extent = model.stat.extent
        self._model.stat.center[:] = model.stat.center
        if self._renderer is None or self._size != (height, width):
            self.close()
            self._renderer = mujoco.Renderer(self._model, height=height, width=width)
            self._size = (height, width)
        self._renderer.update_scene(data, camera=self._camera)
        return self._renderer.render().copy()

    def close(self) -> None:
        """Free the GL context (a later render creates a new one)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
            self._size = None
