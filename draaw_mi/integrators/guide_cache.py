"""When ``draaw_v4`` guides, and its guides: :class:`GuideCache` (one learned guide per scene,
decided by a pilot's indirect share) and :class:`PilotDecision` (the decision taken on
adaptive sampling's pilot, whose paths train the guide). The guide itself, its learning and
its sampling: :mod:`~draaw_mi.integrators.guiding`, whose constants these read at each call.
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np

from . import guiding


def train_paths(samples: int | None) -> int:
    """Camera paths of the training pass for a render of ``samples`` samples (``None``: not
    known): ``samples / TRAIN_SHARE`` within [:data:`~.guiding.MIN_TRAIN_PATHS`, :data:`~.guiding.TRAIN_PATHS`],
    so that the training stays a small part of the render's time."""
    if samples is None:
        return guiding.TRAIN_PATHS
    return int(np.clip(samples // guiding.TRAIN_SHARE, guiding.MIN_TRAIN_PATHS, guiding.TRAIN_PATHS))


class PilotDecision:
    """Guiding's first decision on a scene, taken on adaptive sampling's pilot
    (:meth:`GuideCache.for_primal`): :meth:`records` are the pilot's paths to record, where
    they can be the training's camera paths; called with the pilot's indirect share, it learns the guide
    where the share calls for one, sets it as ``integrator``'s for the main pass and returns
    whether it did.

    The pilot's paths serve the training as well as a pass of their own: camera paths sampled
    by the BSDF alone, as :func:`~.guiding.learn_guide`'s own (spread over the image by pixel
    rather than at random: any spread learns a guide, and the mixture keeps the render unbiased
    whatever it learned; on the glossy panel at 128^2, guides from either read 0.291x
    ``path``'s MSE, eight guides each). Where they are the whole training (:meth:`records`)
    they save it its camera pass: on the glossy panel at 128^2, learning took 10 ms against
    26.5 ms, the records adding 1.2 ms to the pilot; 0.3-2.3 ms (0.2-1 % of a render) in
    scenes the decision leaves unguided (``benchmarks/results/speed_suite.md``).
    """

    def __init__(self, cache: "GuideCache", integrator, scene: mi.Scene, key: tuple, samples: int):
        self.cache, self.integrator, self.scene, self.key = cache, integrator, scene, key
        self.samples = samples
        self._records = None

    def records(self, lanes: int) -> guiding.Records | None:
        """Records for a pilot of ``lanes`` paths, every ``stride``-th lane, as many paths as
        the training takes; ``None`` (the training traces its own) unless they are the whole
        training, one batch of at most :data:`~.guiding.CHUNK_PATHS` (12 MiB at 6 vertices):
        renders of up to about 2^21 samples. In larger ones the pass they would shorten is a
        small share of the render, and they add to the pilot's peak memory (a 1024^2, 256-spp
        render of ``scenes/cornell.toml``: 235 against 223 MiB, 1.27x ``path``'s)."""
        want = train_paths(self.samples)
        if want > min(guiding.CHUNK_PATHS, int(lanes)):
            return None
        # at least the paths the training takes (no pass for a remainder), at most a batch
        stride = max(int(lanes) // want, -(-int(lanes) // guiding.CHUNK_PATHS))
        self._records = guiding.Records(-(-int(lanes) // stride), guiding._record_depth(self.integrator), stride)
        return self._records

    def __call__(self, share: float) -> bool:
        first, self._records = self._records, None
        guide = self.cache.decide(self.integrator, self.scene, self.key, share, self.samples, first)
        self.integrator._guide = guide
        return guide is not None


class GuideCache:
    """``draaw_v4``'s guides, one per scene (its ``selection_key``), learned before the first
    guided primal render or between its adaptive pilot and main pass (:meth:`for_primal`),
    and kept for the scene's lifetime, as the learned light table. ``mode``: ``"auto"``
    (guide where the indirect share, from adaptive sampling's pilot or
    :func:`~.guiding.indirect_share`, is at least :data:`~.guiding.SHARE_MIN`), ``"on"`` or ``"off"``."""

    def __init__(self, mode: str):
        self.mode = mode
        self._entries = {}        # key -> (emitter array, guiding.Guide | None, indirect share)
        self._measured = {}       # key -> (emitter array, indirect share) measured before a decision

    def wanted(self, sensor: mi.Sensor, spp: int, piloted: bool = False) -> bool:
        """Whether a primal render of ``spp`` samples per pixel through ``sensor`` looks for a
        guide: always with ``"on"``; with ``"auto"`` from :data:`~.guiding.AUTO_MIN_SPP` spp and
        :data:`~.guiding.AUTO_MIN_SAMPLES` samples in all, where the decision pilot costs 2.5-4 % of the
        render's time once per scene (previews, fits' iterations and small test
        renders do not pay it), or from :data:`~.guiding.PILOTED_MIN_SAMPLES` when the decision comes
        free with adaptive sampling's pilot (``piloted``: :meth:`decide`)."""
        if self.mode != "auto":
            return self.mode == "on"
        size = sensor.film().crop_size()
        least = guiding.PILOTED_MIN_SAMPLES if piloted else guiding.AUTO_MIN_SAMPLES
        return spp >= guiding.AUTO_MIN_SPP and spp * int(size[0]) * int(size[1]) >= least

    def for_render(self, integrator, scene: mi.Scene, sensor: mi.Sensor, spp: int) -> guiding.Guide | None:
        """The guide for a primal render of ``spp`` samples per pixel through ``sensor``:
        :meth:`guide` where :meth:`wanted`, else ``None``."""
        if not self.wanted(sensor, spp):
            return None
        size = sensor.film().crop_size()
        return self.guide(integrator, scene, integrator.selection_key(scene), spp * int(size[0]) * int(size[1]))

    def for_primal(self, integrator, scene: mi.Scene, sensor: mi.Sensor, spp: int, adaptive: bool):
        """``(guide | None, decide | None)`` for ``draaw_v4``'s primal render of ``spp``
        samples per pixel through ``sensor`` (``adaptive``: whether it renders adaptively
        without a guide). Where adaptive sampling's pilot can decide (:meth:`wanted` with
        ``piloted``) and ``"auto"`` has not decided on the scene yet, no guide and ``decide``,
        a :class:`PilotDecision` for
        :func:`~draaw_mi.integrators.adaptive_sampling.render_adaptive`: the pilot records
        its paths for the training and, given the pilot's indirect share, it learns the guide
        where the share calls for one (:meth:`decide`), sets it as the integrator's for the
        main pass and returns whether it did. A scene ``"auto"`` has decided on keeps its guide (or none) from
        :data:`~.guiding.PILOTED_MIN_SAMPLES` up, however it renders now (``draaw_v4`` renders a decided
        scene stratified, not adaptively). Otherwise :meth:`guide` (cached, or ``"on"``) or
        :meth:`for_render`."""
        key = integrator.selection_key(scene)
        size = sensor.film().crop_size()
        samples = spp * int(size[0]) * int(size[1])
        if self.mode == "auto" and not self.pending(key) and self.wanted(sensor, spp, piloted=True):
            return self.guide(integrator, scene, key, samples), None   # decided: its guide, or none
        if not (adaptive and self.wanted(sensor, spp, piloted=True)):
            return self.for_render(integrator, scene, sensor, spp), None
        if not self.pending(key):
            return self.guide(integrator, scene, key, samples), None
        return None, PilotDecision(self, integrator, scene, key, samples)

    def pilot_decides(self, integrator, scene: mi.Scene, sensor: mi.Sensor, spp: int) -> bool:
        """Whether adaptive sampling's pilot is to decide on guiding for a primal render of
        ``spp`` samples per pixel through ``sensor`` (``"auto"``, the scene undecided, and
        :meth:`wanted` with ``piloted``): ``draaw_v4`` then renders it adaptively, not
        stratified."""
        return self.pending(integrator.selection_key(scene)) and self.wanted(sensor, spp, piloted=True)

    def pending(self, key: tuple) -> bool:
        """Whether ``"auto"`` has yet to decide on the scene of ``key``."""
        return self.mode == "auto" and key not in self._entries

    def guide(self, integrator, scene: mi.Scene, key: tuple, samples: int | None = None) -> guiding.Guide | None:
        """The guide to render ``scene`` with, or ``None``; decided here on a first call
        (``"auto"``: by :func:`~.guiding.indirect_share`'s pilot)."""
        if self.mode == "off":
            return None
        entry = self._entries.get(key)
        if entry is None:
            share = self.indirect_share(integrator, scene, key) if self.mode == "auto" else 1.0
            return self.decide(integrator, scene, key, share, samples)
        return entry[1]

    def indirect_share(self, integrator, scene: mi.Scene, key: tuple) -> float:
        """The indirect share of the scene of ``key``: the one guiding decided on, or
        :func:`~.guiding.indirect_share`'s pilot, run once per scene (V4's path reuse asks
        for it where guiding has not decided, and a later decision takes it)."""
        entry = self._entries.get(key)
        if entry is not None:
            return entry[2]
        measured = self._measured.get(key)
        if measured is None:
            if len(self._measured) >= 4:
                self._measured.pop(next(iter(self._measured)))
            # (the entry holds the emitter array, as _entries' do: a dead scene's key is never reused)
            measured = self._measured[key] = (scene.emitters_dr(), guiding.indirect_share(integrator, scene))
        return measured[1]

    def decide(self, integrator, scene: mi.Scene, key: tuple, share: float,
               samples: int | None = None, first: guiding.Records | None = None) -> guiding.Guide | None:
        """Record ``share`` (the indirect share of the scene of ``key``) and, from
        :data:`~.guiding.SHARE_MIN` up (always with ``"on"``), learn its guide from :data:`~.guiding.TRAIN_PATHS`
        paths, or ``samples / TRAIN_SHARE`` for a render of ``samples`` samples if fewer (the
        training stays a small part of the render's time), ``first`` (paths already recorded)
        among them; returns the guide or ``None``."""
        guide = guiding.learn_guide(integrator, scene, train_paths(samples), first) \
            if share >= guiding.SHARE_MIN or self.mode == "on" else None
        if len(self._entries) >= 4:
            self._entries.pop(next(iter(self._entries)))
        self._entries[key] = (scene.emitters_dr(), guide, share)
        return guide

    def share(self, key: tuple) -> float | None:
        """The indirect share measured for the scene of ``key`` (``None``: not yet)."""
        entry = self._entries.get(key)
        return None if entry is None else entry[2]

    def forget(self, scene_id: int) -> None:
        for key in [k for k in self._entries if k[0] == scene_id]:
            del self._entries[key]
        for key in [k for k in self._measured if k[0] == scene_id]:
            del self._measured[key]
