"""bouncecal: damping of granular contact laws from the sound of a bouncing ball.

The functions mirror the CLI's commands; their keyword arguments are the commands' flags in
snake_case (--min-snr-db -> min_snr_db) and their results are the commands' --json output as
dicts and lists (the same keys and nesting: `json.loads` of the CLI's output compares equal).

    import bouncecal
    d = bouncecal.detect("data/default_steel_copper.flac")
    a = bouncecal.analyze("data/default_steel_copper.flac", scene="data/default_steel_copper.toml")
    c = bouncecal.calibrate("data/default_steel_copper.flac", scene="data/default_steel_copper.toml")
    s = bouncecal.simulate(law="walton-braun", set={"gamma": 0.5}, height=0.2)
    bouncecal.columns(a["bounces"])["e"]          # a NumPy array per key

Audio in memory (sounddevice, a notebook, a DAQ) is a NumPy array with its rate, and a live
stream is a Listener (the same streaming stages as `bouncecal serve` and `bouncecal listen`):

    a = bouncecal.analyze(samples, rate=48000, height=0.2)      # 1-D mono or [channel, frame]
    live = bouncecal.Listener(48000, height=0.2)
    for block in blocks:                                        # e.g. sounddevice's callback
        for m in live.feed(block):                              # impacts as they become final
            if m["type"] == "impact": print(m["impact"]["time_s"])
    analysis = live.finish()                                    # the whole take's analysis

A scene is a TOML file's path or a dict of its keys, dotted ({"ball.diameter_m": 0.01,
"drop.height_m": 0.2, "law.parameters.A": 5.16e-7}) or nested ({"ball": {"diameter_m": 0.01}}).
Errors raise bouncecal.Error subclasses carrying the CLI's message, code name and exit code.
"""

import json as _json
import math as _math
import os as _os
import re as _re

from . import _core
from ._errors import (BadParameterError, BadSamplesError, BadSceneError, Error,  # noqa: F401
                      FitFailedError, FitOutcomeError, InputMissingError, InternalError,
                      NoBouncesError, NotAudioError, OutputError, SilenceError, SomeFailedError,
                      UsageError)

__version__ = _core.version

_BARE_KEY = _re.compile(r"^[A-Za-z0-9_-]+$")


def _flatten(prefix, value, out):
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    else:
        out[prefix] = value


def _toml_value(key, v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not _math.isfinite(v):
            raise BadSceneError(f"scene dict: {key}: not a finite number ({v!r})")
        return repr(v)
    if isinstance(v, str):
        return _json.dumps(v)  # a TOML basic string (JSON escapes are TOML escapes)
    raise TypeError(f"scene dict: {key}: expected a number, bool or string, got {type(v).__name__}")


def scene_toml(scene):
    """The TOML text of a scene dict (dotted or nested keys), as a scene file would hold it."""
    flat = {}
    _flatten("", scene, flat)
    lines = []
    for key, v in flat.items():
        parts = key.split(".")
        quoted = ".".join(p if _BARE_KEY.match(p) else _json.dumps(p) for p in parts)
        lines.append(f"{quoted} = {_toml_value(key, v)}")
    return "\n".join(lines) + "\n"


def _scene_options(scene, opts):
    if scene is None:
        return
    if isinstance(scene, dict):
        opts["scene"] = "scene dict"
        opts["scene_text"] = scene_toml(scene) if scene else "# empty scene dict\n"
    else:
        opts["scene"] = _os.fspath(scene)


def _law_sets(value):
    """set={"gamma": 0.5} or ["gamma=0.5"] -> ["gamma=0.5"] (the CLI's --set NAME=VALUE)."""
    if value is None:
        return None
    if isinstance(value, dict):
        return [f"{k}={float(v)!r}" for k, v in value.items()]
    if isinstance(value, str):
        return [value]
    return [str(s) for s in value]


def _paths(value):
    if value is None:
        return None
    if isinstance(value, (str, bytes, _os.PathLike)):
        return [_os.fspath(value)]
    return [_os.fspath(v) for v in value]


def _put(opts, name, value, kind):
    """Adds an option the caller set (None: not set; False flags are not set either)."""
    if value is None or value is False:
        return
    if kind is float:
        opts[name] = float(value)
    elif kind is int:
        opts[name] = int(value)
    elif kind is bool:
        opts[name] = bool(value)
    else:
        opts[name] = str(value)


def _scene_flags(opts, scene, height, height_sigma, impact_speed, diameter, density, mass,
                 material, drag, buoyancy, contact_duration, g):
    _scene_options(scene, opts)
    _put(opts, "height", height, float)
    _put(opts, "height_sigma", height_sigma, float)
    _put(opts, "impact_speed", impact_speed, float)
    _put(opts, "diameter", diameter, float)
    _put(opts, "density", density, float)
    _put(opts, "mass", mass, float)
    _put(opts, "material", material, str)
    _put(opts, "drag", drag, str)
    _put(opts, "buoyancy", buoyancy, bool)
    _put(opts, "contact_duration", contact_duration, bool)
    _put(opts, "g", g, float)


def _detect_flags(opts, channel, start, end, sequence, min_snr_db, impacts):
    _put(opts, "channel", channel, str)
    _put(opts, "start", start, float)
    _put(opts, "end", end, float)
    _put(opts, "sequence", sequence, str)
    _put(opts, "min_snr_db", min_snr_db, float)
    if impacts is not None:
        opts["impacts"] = _paths(impacts)


def laws(name=None, *, scene=None):
    """`bouncecal laws --json`: {"laws": [{name, summary, formula, source, end_rule, state_size,
    parameters: [{name, unit, lower, upper, default, damping, description}], closed_forms}]}.
    scene: a scene file whose materials set the defaults (Hertz stiffness)."""
    opts = {}
    _put(opts, "name", name, str)
    if scene is not None:
        opts["scene"] = _os.fspath(scene)
    return _core.laws(opts)


def simulate(*, scene=None, params=None, height=None, height_sigma=None, impact_speed=None,
             diameter=None, density=None, mass=None, material=None, drag=None, buoyancy=False,
             contact_duration=False, g=None, law=None, set=None, expression=None, rtol=None,
             horizon=None, max_impacts=None, integrate=False):
    """`bouncecal simulate --json`: {law: {name, parameters}, impacts: [...], energy: {...},
    stop_reason, stop_detail, total_steps}. set: law parameters, {"gamma": 0.5} or
    ["gamma=0.5"]; params: replay a parameter file (no scene option with it)."""
    opts = {}
    _scene_flags(opts, scene, height, height_sigma, impact_speed, diameter, density, mass,
                 material, drag, buoyancy, contact_duration, g)
    _put(opts, "params", None if params is None else _os.fspath(params), str)
    _put(opts, "law", law, str)
    if set is not None:
        opts["set"] = _law_sets(set)
    _put(opts, "expression", expression, str)
    _put(opts, "rtol", rtol, float)
    _put(opts, "horizon", horizon, float)
    _put(opts, "max_impacts", max_impacts, int)
    _put(opts, "integrate", integrate, bool)
    return _core.simulate(opts)


def export(params, output, *, to, scene="bounce", force=False, allow_approximation=False,
           impacts=None, dt_e_error=None, packing_time=None, particles=None,
           packing_restitution=None):
    """`bouncecal export PARAMS --to TARGET -o OUTPUT --json`: writes the directory a DEM
    simulator runs (lammps, liggghts, yade) and returns its mapping (also DIR/mapping.json)."""
    opts = {"to": str(to), "scene": str(scene)}
    _put(opts, "force", force, bool)
    _put(opts, "allow_approximation", allow_approximation, bool)
    _put(opts, "impacts", impacts, int)
    _put(opts, "dt_e_error", dt_e_error, float)
    _put(opts, "packing_time", packing_time, float)
    _put(opts, "particles", particles, int)
    _put(opts, "packing_restitution", packing_restitution, float)
    return _core.export(_os.fspath(params), _os.fspath(output), opts)


def _files(files):
    """(paths, single): a str/PathLike is one recording (its result is the object itself, as
    the CLI prints for one file); a list gives a list (one entry per result)."""
    if files is None:
        return [], False
    if isinstance(files, (str, bytes, _os.PathLike)):
        return [_os.fspath(files)], True
    return [_os.fspath(f) for f in files], False


def _listed(result, single):
    if single or isinstance(result, list):
        return result
    return [result]


def _is_array(x):
    """A NumPy array (or anything exposing the array interface), not a path or list of paths."""
    return hasattr(x, "__array_interface__") or hasattr(x, "__array__")


def _samples(x):
    import numpy as np

    return np.ascontiguousarray(np.asarray(x, dtype=np.float32))


def _array_call(fn, files, rate, name, opts):
    if rate is None:
        raise UsageError("audio given as an array needs its rate: rate=48000")
    if name is not None:
        opts["name"] = str(name)
    return fn(_samples(files), float(rate), opts)


def detect(files=None, *, channel=None, start=None, end=None, sequence=None, min_snr_db=None,
           impacts=None, hop_ms=None, no_refine=False, rate=None, name=None):
    """`bouncecal detect FILE... --json` (schema bouncecal.detect/2): the sequences, each with its
    impacts (time_sigma_s ...; listed once: d["sequences"][d["chosen_sequences"][0]]["impacts"]
    are the chosen sequence's), removed candidates, channel scores, warnings.
    files: one path (-> one dict) or a list (-> a list; a failed recording is an entry
    {"file", "error"} and SomeFailedError is raised with .result = the list).
    channel: "auto" (default), "mix" or an index; sequence: "main" (default), "all" or an index;
    impacts: impact-time file(s) instead of detection.
    files may also be a NumPy array (1-D mono or 2-D [channel, frame], full scale 1) with
    rate=HZ (and name=..., "array" by default): the result is that of a file of those samples."""
    opts = {}
    _detect_flags(opts, channel, start, end, sequence, min_snr_db, impacts)
    if _is_array(files):
        return _array_call(_core.detect_array, files, rate, name, opts)
    paths, single = _files(files)
    _put(opts, "hop_ms", hop_ms, float)
    _put(opts, "no_refine", no_refine, bool)
    return _listed(_core.detect(paths, opts), single)


def analyze(files=None, *, scene=None, height=None, height_sigma=None, impact_speed=None,
            diameter=None, density=None, mass=None, material=None, drag=None, buoyancy=False,
            contact_duration=False, g=None, contact_time=None, channel=None, start=None,
            end=None, sequence=None, min_snr_db=None, impacts=None, rate=None, name=None):
    """`bouncecal analyze FILE... --json` (schema bouncecal.analysis/1): per-bounce speeds,
    restitution e and energy loss eta with sigmas, the summary, assumed values, warnings.
    One path gives one dict (a list when sequence="all" finds several); a list gives a list.
    files may be a NumPy array with rate=HZ (as detect)."""
    opts = {}
    _detect_flags(opts, channel, start, end, sequence, min_snr_db, impacts)
    _scene_flags(opts, scene, height, height_sigma, impact_speed, diameter, density, mass,
                 material, drag, buoyancy, contact_duration, g)
    _put(opts, "contact_time", contact_time, float)
    if _is_array(files):
        return _array_call(_core.analyze_array, files, rate, name, opts)
    paths, single = _files(files)
    return _listed(_core.analyze(paths, opts), single)


def calibrate(files=None, *, scene=None, height=None, height_sigma=None, impact_speed=None,
              diameter=None, density=None, mass=None, material=None, drag=None, buoyancy=False,
              contact_duration=False, g=None, law=None, set=None, expression=None, strategy=None,
              free=None, fix=None, derivatives=None, rtol=None, loss=None, loss_scale=None,
              max_iterations=None, starts=None, ignore_drop=False, no_scatter=False,
              channel=None, start=None, end=None, sequence=None, min_snr_db=None, impacts=None,
              output=None, force=False, jobs=None, batch=False, rate=None, name=None):
    """`bouncecal calibrate FILE... --json`: the parameter file's object (bouncecal.params/2)
    with "assumed"; several files are one joint fit. law="all": the law comparison
    (bouncecal.law_comparison/2); batch=True: one bouncecal.calibration_row/1 per file (a list).
    output: also write the parameter file (force replaces it).
    An outcome other than "converged" raises FitOutcomeError (.exit_code 13/14/15, .result the
    calibration, the file still written); law="all" with no adequate law raises FitFailedError
    (.result the comparison); batch with failures raises SomeFailedError (.result the rows).
    files may be a NumPy array with rate=HZ (as detect; its provenance is the samples' SHA-256)."""
    opts = {}
    _detect_flags(opts, channel, start, end, sequence, min_snr_db, impacts)
    _scene_flags(opts, scene, height, height_sigma, impact_speed, diameter, density, mass,
                 material, drag, buoyancy, contact_duration, g)
    _put(opts, "law", law, str)
    if set is not None:
        opts["set"] = _law_sets(set)
    _put(opts, "expression", expression, str)
    _put(opts, "strategy", strategy, str)
    for key, value in (("free", free), ("fix", fix)):
        if value is not None:
            opts[key] = [value] if isinstance(value, str) else [str(v) for v in value]
    _put(opts, "derivatives", derivatives, str)
    _put(opts, "rtol", rtol, float)
    _put(opts, "loss", loss, str)
    _put(opts, "loss_scale", loss_scale, float)
    _put(opts, "max_iterations", max_iterations, int)
    _put(opts, "starts", starts, int)
    _put(opts, "ignore_drop", ignore_drop, bool)
    _put(opts, "no_scatter", no_scatter, bool)
    _put(opts, "output", None if output is None else _os.fspath(output), str)
    _put(opts, "force", force, bool)
    _put(opts, "jobs", jobs, int)
    _put(opts, "batch", batch, bool)
    if _is_array(files):
        return _array_call(_core.calibrate_array, files, rate, name, opts)
    paths, _ = _files(files)
    return _core.calibrate(paths, opts)


class Listener:
    """A live stream, detected as it arrives (the streaming stages of `bouncecal serve` and
    `bouncecal listen`, include/bouncecal/acoustic/live.hpp).

    feed(samples) takes the next samples (1-D mono, or [channel, frame]: mixed) and returns the
    messages (bouncecal.live/1 dicts) of what became final: {"type": "impact", "impact": {...},
    "bounce": {...} or None}, {"type": "revised", ...}, {"type": "warning", ...}.
    finish() ends the stream and returns the whole take's analysis (bouncecal.analysis/1, what
    `analyze` gives for a file of the same samples); the last messages are then in
    .last_messages, every final impact in .impacts.
    The take is kept in memory (4 bytes a sample), or written to take=PATH (.flac or .wav) as
    it arrives. Scene keywords as analyze's."""

    def __init__(self, rate, *, scene=None, height=None, height_sigma=None, impact_speed=None,
                 diameter=None, density=None, mass=None, material=None, drag=None,
                 buoyancy=False, contact_duration=False, g=None, min_snr_db=None, take=None,
                 force=False, name=None):
        opts = {}
        _scene_flags(opts, scene, height, height_sigma, impact_speed, diameter, density, mass,
                     material, drag, buoyancy, contact_duration, g)
        _put(opts, "min_snr_db", min_snr_db, float)
        _put(opts, "take", None if take is None else _os.fspath(take), str)
        _put(opts, "force", force, bool)
        _put(opts, "name", name, str)
        self._core = _core.Listener(float(rate), opts)

    def feed(self, samples):
        x = _samples(samples)
        if x.ndim == 2:
            x = _samples(x.mean(axis=0))
        return self._core.feed(x)

    def finish(self):
        return self._core.finish()

    @property
    def impacts(self):
        return self._core.impacts

    @property
    def last_messages(self):
        return self._core.last_messages

    @property
    def rate(self):
        return self._core.rate

    @property
    def frames(self):
        return self._core.frames


def read_audio(path):
    """The waveform: {file, sample_rate_hz, channels, frames, duration_s, format, codec, decoder,
    lossy, samples}; samples is a float32 NumPy array [channel, frame] in [-1, 1]."""
    return _core.read_audio(_os.fspath(path))


def columns(records):
    """A list of result records (impacts, bounces, ...) as one NumPy array per key; None (an
    unknown value) becomes NaN in numeric columns."""
    import numpy as np

    out = {}
    keys = []
    for r in records:
        for k in r:
            if k not in keys:
                keys.append(k)
    for k in keys:
        values = [r.get(k) for r in records]
        present = [v for v in values if v is not None]
        if present and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
            out[k] = np.array([np.nan if v is None else v for v in values], dtype=float)
            if all(isinstance(v, int) for v in values):
                out[k] = out[k].astype(np.int64)
        elif present and all(isinstance(v, bool) for v in present):
            out[k] = np.array([bool(v) for v in values])
        else:
            out[k] = np.array(values, dtype=object)
    return out
