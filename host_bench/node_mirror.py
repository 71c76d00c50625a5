"""What the node must publish for a given sequence of bus frames: the reference twin of
firmware/node/nte_node.c.

The mirror sees the frames in the order the node received them (the bench's own frames, or a
capture of the whole bus) and repeats the node's input rules -- E2E (length, counter, CRC),
DBC ranges on the raw values, one 16-bit sensor clock unwrapped for both streams, samples not
later than their stream's previous one rejected, depth interpolated linearly to each force
time in float32 (same operations, same order), the stale rule, the Command frame -- and runs
reference_py's FilterBank in float32 with the node's configuration.  Its outputs are encoded
as the C frame layer encodes them (float32 division by the scale, round half away from zero,
clamping to the signal's range), so the node's frames are expected to match bit for bit.
Predict-only (nte_node.h PREDICT-ONLY) as the node: Command.ForceSource 2/1, force samples
flagged SensorFault, and a lost force sensor bridged by steps on the depth stream; Adapting 0
while the model alone publishes.
Model III (``model=3`` or a Command with ModelSel 3) runs with the contact front end on, as the
node does: Params cycle 0..9 (7 g_fast, 8 g_slow, 9 delta), InTissue is the front end's contact state,
and the Contact frames (``contacts``) follow the node's rule (nte_node.h, MODEL III).  The
Health frames (``healths``, every model) follow nte_node.h HEALTH.  The frames' records and
their reading back from a capture are in node_outputs.py.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable

import numpy as np

from reference_py.bank import (STATUS_CLIPPED, STATUS_DIVERGED, STATUS_FILTER_RESET,
                               STATUS_FLOORED, STATUS_GATED, STATUS_REJECTED,
                               STATUS_SIGN_UNCERTAIN, FilterBank, identified_names)
from reference_py.bus.dbc import FRAME_LENGTH, NteDatabase
from reference_py.config import ContactConfig, EstimatorConfig
from reference_py.contact import CONTACT_TISSUE
from reference_py.tools.estimate import make_config
from reference_py.fmath import real_for
from reference_py.params import ALL_NAMES, PRESETS, RELAX_NOMINAL
from reference_py.robust import STATUS_CONVERGED, STATUS_REFINED, STATUS_REFINING

from .node_outputs import ContactOut, EstimateOut, HealthOut, ParamOut
from .setting_transfer import SettingTransfer

F32 = np.float32
TICK_US = 100
#: the envelope (EstimatorConfig's accepted ranges), which the DBC's signals span exactly
#: (tests/python/test_envelope.py): the node's frame layer refuses inputs and clamps outputs there
DEPTH_MAX_MM = EstimatorConfig.depth_max_mm
SPEED_MAX_MM_S = EstimatorConfig.speed_max_mm_s
FORCE_MAX_N = EstimatorConfig.force_max_n
#: raw ranges of the input signals: the envelope in the DBC's steps (1 um, 0.01 mm/s, 0.1 mN)
DEPTH_RAW = (0, round(DEPTH_MAX_MM / 1e-3))
VELOCITY_RAW = (-round(SPEED_MAX_MM_S / 1e-2), round(SPEED_MAX_MM_S / 1e-2))
FORCE_RAW = (-round(FORCE_MAX_N / 1e-4), round(FORCE_MAX_N / 1e-4))
#: the node's header: its defaults and periods are read from its #define lines (one source)
NODE_H = Path(__file__).resolve().parents[1] / "firmware" / "node" / "nte_node.h"


def node_defines(path: Path = NODE_H) -> dict[str, int]:
    """Every integer ``#define NTE_NODE_<NAME> <value>[u]`` of the header, by NAME."""
    return {m.group(1): int(m.group(2)) for m in re.finditer(
        r"^#define NTE_NODE_(\w+) (\d+)u?\s*$", path.read_text(), re.MULTILINE)}


NODE = node_defines()
#: Contact frames: at least every this many sensor ticks when nothing changes (100 ms)
CONTACT_PERIOD_TICKS = NODE["CONTACT_PERIOD_US"] // TICK_US
#: Health frames: likewise (nte_node.h HEALTH)
HEALTH_PERIOD_TICKS = NODE["HEALTH_PERIOD_US"] // TICK_US
#: a filter's status bits in the order of the Health frame's Filter<i>Flags bits 0..5 (the DBC)
HEALTH_FILTER_BITS = (STATUS_GATED, STATUS_FILTER_RESET, STATUS_DIVERGED, STATUS_CLIPPED,
                      STATUS_FLOORED, STATUS_SIGN_UNCERTAIN)
#: steps on the Depth stream while the force sensor is lost: at least this many sensor ticks
#: apart (nte_node.h NTE_NODE_PREDICT_PERIOD_US, 5 ms)
PREDICT_PERIOD_TICKS = NODE["PREDICT_PERIOD_US"] // TICK_US


def roundf(x: np.float32) -> int:
    """C roundf of a float32 to an integer (half away from zero)."""
    v = float(x)
    return int(math.floor(abs(v) + 0.5)) * (1 if v >= 0 else -1)


def quantise(value: float, scale: float, lo: float, hi: float) -> tuple[int, bool]:
    """The generated encoder after the frame layer's clamp: (raw, clamped)."""
    v = F32(value)
    clamped = False
    if v < F32(lo):
        v, clamped = F32(lo), True
    elif v > F32(hi):
        v, clamped = F32(hi), True
    return roundf(F32(v / F32(scale))), clamped


def std_log10(sd: np.float32) -> np.float32:
    """nte_frames.c's log10 of a standard deviation, float operation by float operation:
    std = 2^e m, m in [sqrt(1/2), sqrt(2)), ln m = 2 atanh((m - 1)/(m + 1)) to the t^9 term;
    below 1e-33 the Params frame's range end."""
    sd = F32(sd)
    if sd < F32(1e-33):
        return F32(-32.767)
    bits = int(np.array([sd], dtype=np.float32).view(np.uint32)[0])
    e = ((bits >> 23) & 0xFF) - 127
    m = np.array([(bits & 0x007FFFFF) | 0x3F800000], dtype=np.uint32).view(np.float32)[0]
    if m > F32(1.41421356):
        m, e = F32(m * F32(0.5)), e + 1
    one = F32(1.0)
    t = F32(F32(m - one) / F32(m + one))
    t2 = F32(t * t)
    series = F32(one / F32(9.0))
    for k in (7.0, 5.0, 3.0):
        series = F32(F32(one / F32(k)) + F32(t2 * series))
    series = F32(one + F32(t2 * series))
    ln_m = F32(F32(F32(2.0) * t) * series)
    return F32(F32(F32(F32(e) * F32(0.693147181)) + ln_m) * F32(0.434294482))


def param_count(model: int) -> int:
    """Params multiplexer indices cycled by a model: 0..6, Model III 0..9."""
    return 10 if model == 3 else 7


@dataclass
class NodeMirror:
    preset: str = "paper-10mms"
    model: int = NODE["DEFAULT_MODEL"]
    base_id: int | None = None
    depth_timeout_us: int = NODE["DEFAULT_DEPTH_TIMEOUT_US"]
    resync_gap_us: int = NODE["DEFAULT_RESYNC_GAP_US"]
    command_interval_us: int = NODE["DEFAULT_COMMAND_INTERVAL_US"]
    params_per_step: int = NODE["DEFAULT_PARAMS_PER_STEP"]
    db: NteDatabase = field(init=False)
    estimates: list[EstimateOut] = field(default_factory=list)
    params: list[ParamOut] = field(default_factory=list)
    contacts: list[ContactOut] = field(default_factory=list)
    healths: list[HealthOut] = field(default_factory=list)
    #: per estimate: (t_s of the force sample, force_n, depth_mm used, params snapshot)
    trace: list[tuple[float, float, float, list[float], list[float]]] = field(default_factory=list)
    events: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.db = NteDatabase(base_id=self.base_id)
        self.R = real_for("float32")
        self.rx = self.db.receiver()
        self.clock_raw: int | None = None
        self.clock_ticks = 0
        self.depth: list[tuple[int, np.float32, np.float32]] = []   # (t, d, v), newest last
        self.forces: list[tuple[int, np.float32]] = []
        self.last_force_t: int | None = None
        #: per stream, a sample held for a time jump (nte_node_pending_t)
        self.pending: dict[str, dict | None] = {"Depth": None, "Force": None}
        self.param_next = 0
        self.last_command_us: int | None = None
        self._last_e2e_status = "ok"
        # a configuration transfer (nte_node.h SETTINGS)
        self.transfer = SettingTransfer(self.db)
        # predict-only (nte_node.h PREDICT-ONLY): commanded, the mode of the last step, whether
        # that step was on the depth stream, its time; and the node's counters of it
        self.force_cmd_model = False
        self.predicting = False
        self.depth_stepped = False
        self.step_t: int | None = None
        self.depth_since_force: int | None = None   # first depth sample after the newest force
        self.predict_counts = {"predict_on": 0, "predict_off": 0, "predict_depth_steps": 0}
        # the sensor watch (nte_node.h SENSOR WATCH): the last unflagged reading, how many
        # times in a row it came, the depth when it first came
        self.watch_force = F32(0.0)
        self.watch_run = 0
        self.watch_depth = F32(0.0)
        self._start(self.model)

    # ------------------------------------------------------------------ estimator
    def _cfg(self, model: int):
        p = PRESETS[self.preset]
        cfg = make_config(p, model, "default", "all")
        if model == 3:
            # as nte-node (and nte-run --model 3): the stage position in, the front end on
            cfg = replace(cfg, contact=ContactConfig(enabled=True))
        return cfg, p.params.as_list()

    def _start(self, model: int, estimator: str = "bank") -> None:
        cfg, nominal = self._cfg(model)
        self.model = model
        self.estimator = estimator
        self.cfg = cfg
        self.nominal = nominal
        if estimator == "robust":
            from reference_py.robust import RobustEstimator
            self.bank = RobustEstimator(self.R, cfg, [nominal])
        else:
            self.bank = FilterBank(self.R, cfg, [nominal])
        self.stepped = False
        self.last = EstimateOut(0, 0, 0, 0, 1, 0, 0, 0)
        self.last_vals = (0.0, 0.0, 0.0)
        self.identified = identified_names(self.cfg)
        self.par_vals = [0.0] * len(self.identified)
        self.par_sd = [0.0] * len(self.identified)
        self.contact_last: tuple[int, ContactOut] | None = None   # (ticks, frame) last sent
        self.health_last: tuple[int, tuple] | None = None          # (ticks, content) last sent
        self._fixed_params()

    def _fixed_params(self) -> None:
        # Model III's turn-over length starts at presliding_mm (nte_node.c alike)
        vals = [F32(v) for v in self.nominal] + [F32(RELAX_NOMINAL[n]) for n in ("g_fast",
                                                                                  "g_slow")] + [
            F32(self.cfg.presliding_mm)]
        if self.model == 1:
            vals[6] = F32(self.cfg.beta0)
        self.fixed_vals = vals

    def _all_params(self) -> tuple[list[np.float32], list[np.float32]]:
        vals = list(self.fixed_vals)
        sds = [F32(0.0)] * len(vals)
        for k, name in enumerate(self.identified):
            j = ALL_NAMES.index(name)
            vals[j] = F32(self.par_vals[k]) if self.stepped else F32(0.0)
            sds[j] = F32(self.par_sd[k]) if self.stepped else F32(0.0)
        return vals, sds

    def _count(self, name: str) -> None:
        self.events[name] = self.events.get(name, 0) + 1

    # ------------------------------------------------------------------ outputs
    def _publish(self, est: EstimateOut, t_s: float, force: float, depth: float) -> None:
        self.estimates.append(est)
        vals, sds = self._all_params()
        count = param_count(self.model)
        for _ in range(self.params_per_step):
            if self.param_next >= count:
                self.param_next = 0          # after a change from Model III to I or II
            j = self.param_next
            self.param_next = (j + 1) % count
            sd = sds[j]
            if sd == 0:
                std_raw = -32768
            else:
                lg = std_log10(sd)
                lg = min(max(lg, F32(-32.767)), F32(32.767))
                std_raw = roundf(F32(lg / F32(0.001)))
            self.params.append(ParamOut(j, vals[j], std_raw))
        self.trace.append((t_s, force, depth, [float(v) for v in vals], [float(s) for s in sds]))

    def _hold(self, t: int, force: np.float32) -> None:
        self._count("stale")
        e = EstimateOut(**{**self.last.__dict__, "stale": 1})
        _, c0 = quantise(self.last_vals[0], 1e-4, -FORCE_MAX_N, FORCE_MAX_N)
        _, c1 = quantise(self.last_vals[1], 4e-4, -0.8192, 0.8188)
        _, c2 = quantise(self.last_vals[2], 5e-4, -8.192, 8.1915)
        e.saturated = int(c0 or c1 or c2)
        self._publish(e, self._t_s(t), float(force), float("nan"))

    def _step(self, t: int, force: np.float32, d: np.float32, v: np.float32,
              fault: bool = False, on_depth: bool = False) -> None:
        po = self.force_cmd_model or fault or on_depth
        if po != self.predicting:
            self.predict_counts["predict_on" if po else "predict_off"] += 1
            self.predicting = po
        self.bank.set_predict_only(po)
        self.step_t = t
        self.depth_stepped = on_depth
        o = self.bank.step(np.array([t * TICK_US], dtype=np.int64), np.array([d], dtype=F32),
                           np.array([v], dtype=F32), np.array([force], dtype=F32))
        self.stepped = True
        fh, z, inn, st = F32(o.force_hat[0]), F32(o.z[0]), F32(o.innovation[0]), int(o.status[0])
        self.par_vals = [float(x) for x in o.params[:, 0]]
        self.par_sd = [float(x) for x in o.params_sd[:, 0]]
        fr, c0 = quantise(fh, 1e-4, -FORCE_MAX_N, FORCE_MAX_N)
        ir, c1 = quantise(inn, 4e-4, -0.8192, 0.8188)
        zr, c2 = quantise(z, 5e-4, -8.192, 8.1915)
        front_end = self.cfg.contact.enabled
        in_tissue = int(o.contact[0] == CONTACT_TISSUE) if front_end else int(d > 0)
        e = EstimateOut(fr, ir, zr, in_tissue, int(not po and not self.bank.frozen),
                        int(c0 or c1 or c2), int((st & STATUS_REJECTED) != 0), 0)
        self.last = e
        self.last_vals = (fh, inn, z)
        self._publish(e, self._t_s(t), float(force), float(d))
        if front_end:
            self._contact(t, F32(o.surface_mm[0]), F32(o.tare_n[0]), int(o.contact[0]),
                          int(o.layer[0]))
        conf = F32(self.bank.confidence[0]) if self.estimator == "robust" else F32(0.0)
        self._health(t, st, conf, [int(w) for w in o.filter_status[:, 0]])

    def _contact(self, t: int, surface: np.float32, tare: np.float32, state: int,
                 layer: int) -> None:
        """The node's Contact frame rule: on a change of state, layer, surface validity or
        surface, else once CONTACT_PERIOD_TICKS of sensor time have passed (or time went
        back)."""
        valid = not bool(np.isnan(surface))
        s_raw = roundf(F32(surface / F32(0.001))) if valid else 0
        t_raw, _ = quantise(tare, 1e-4, -FORCE_MAX_N, FORCE_MAX_N)
        c = ContactOut(int(state == CONTACT_TISSUE), int(valid), self.model - 1, s_raw, t_raw,
                       layer)
        if self.contact_last is not None:
            t0, prev = self.contact_last
            changed = (prev.contact_state != c.contact_state or prev.layer != c.layer
                       or prev.surface_valid != c.surface_valid
                       or self._contact_surface != (float(surface) if valid else 0.0))
            if not changed and 0 <= t - t0 < CONTACT_PERIOD_TICKS:
                return
        self.contact_last = (t, c)
        self._contact_surface = float(surface) if valid else 0.0
        if valid and abs(float(surface)) > DEPTH_MAX_MM + 0.0005:   # half a 1 um step over
            self._count("encode_error")
            return
        self.contacts.append(c)

    def _health(self, t: int, status: int, confidence: np.float32, words: list[int]) -> None:
        """The node's Health frame rule: on a change of any field, else once
        HEALTH_PERIOD_TICKS of sensor time have passed (or time went back)."""
        conf = min(confidence, F32(1.0)) if confidence > 0 else F32(0.0)   # NaN: 0
        flags = tuple(sum(1 << b for b, bit in enumerate(HEALTH_FILTER_BITS) if w & bit)
                      for w in words)
        content = (int((status & STATUS_REFINED) != 0), int((status & STATUS_CONVERGED) != 0),
                   float(conf), flags, int((status & STATUS_REFINING) != 0))
        if self.health_last is not None:
            t0, prev = self.health_last
            if prev == content and 0 <= t - t0 < HEALTH_PERIOD_TICKS:
                return
        self.health_last = (t, content)
        raw, _ = quantise(conf, 1e-4, 0.0, 1.0)
        self.healths.append(HealthOut(content[0], content[1], raw, flags, content[4]))

    def _t_s(self, t: int) -> float:
        return (t - 65536) * 1e-4

    # ------------------------------------------------------------------ force scheduling
    def _decide(self, t: int, force: np.float32, fault: bool = False) -> bool:
        timeout = self.depth_timeout_us // TICK_US
        if not self.depth:
            if self.last_force_t is not None and self.last_force_t - t > timeout:
                self._hold(t, force)
                return True
            return False
        tn = self.depth[-1][0]
        if tn < t:
            if t - tn > timeout or (self.last_force_t or t) - tn > timeout:
                p = self.pending["Depth"]
                if (p is not None and 0 <= t - p["t"] <= timeout
                        and (self.last_force_t or t) - p["t"] <= timeout):
                    return False        # a held depth sample may decide it: wait
                self._hold(t, force)
                return True
            return False
        b = self.depth[-1]
        for a in reversed(self.depth):
            if a[0] <= t:
                # stale, or the estimator predicted past this sample on the depth stream (the
                # sensor was lost: that step's depth sample is at or after t, so we are here)
                if t - a[0] > timeout or (self.depth_stepped and t <= self.step_t):
                    self._hold(t, force)
                elif a[0] == t:
                    self._step(t, force, a[1], a[2], fault)
                else:
                    w = F32(F32(t - a[0]) / F32(b[0] - a[0]))
                    d = F32(a[1] + F32(w * F32(b[1] - a[1])))
                    v = F32(a[2] + F32(w * F32(b[2] - a[2])))
                    self._step(t, force, d, v, fault)
                return True
            b = a
        self._hold(t, force)
        return True

    def _process(self) -> None:
        while self.forces:
            t, f, fault = self.forces[0]
            if not self._decide(t, f, fault):
                return
            self.forces.pop(0)

    def _depth_predict(self) -> None:
        """The node's nte_node_depth_predict: a sensor lost for longer than the timeout (no
        force sample waiting) is bridged by a predict-only step on the newest depth sample."""
        timeout = self.depth_timeout_us // TICK_US
        t, d, v = self.depth[-1]
        if (self.last_force_t is None or self.forces or self.depth_since_force is None
                or t - self.depth_since_force <= timeout
                or (self.step_t is not None and t - self.step_t < PREDICT_PERIOD_TICKS)):
            return
        self.predict_counts["predict_depth_steps"] += 1
        self._step(t, F32(0.0), d, v, True, True)

    # ------------------------------------------------------------------ input
    def _unwrap(self, raw: int, clock: tuple[int | None, int] | None = None) -> tuple[int, int]:
        """Unwrapped ticks of a 16-bit SensorTime against `clock` (default the shared one)."""
        clock_raw, clock_ticks = clock if clock is not None else (self.clock_raw, self.clock_ticks)
        if clock_raw is None:
            return raw + 65536, raw
        d = (raw - clock_raw) & 0xFFFF
        if d >= 0x8000:
            d -= 0x10000
        return clock_ticks + d, raw

    _E2E_EVENT = {"wrong_length": "wrong_dlc", "bad_crc": "bad_crc",
                  "repeated": "counter_repeated", "bad_counter": "counter_invalid"}

    def _e2e_try(self, name: str, data: bytes, state: int | None) -> tuple[str, int | None]:
        """E2E check of `data` against the counter state `state` (None: not synced), without
        touching the receiver: (status, state after)."""
        saved = self.rx.last.pop(name, None)
        if state is not None:
            self.rx.last[name] = state
        status, _ = self.rx.check(name, data)
        after = self.rx.last.pop(name, None)
        if saved is not None:
            self.rx.last[name] = saved
        return status, after

    def _commit_e2e(self, name: str, state: int | None, status: str) -> None:
        if state is not None:
            self.rx.last[name] = state
        if status == "skipped":
            self._count("counter_skipped")

    def _decode_sample(self, name: str, data: bytes, state: int | None):
        """(status, state after, sample (raw_t, a, b) or None); status 'out_of_range' for an
        E2E-valid frame with a raw value outside the DBC range."""
        status, after = self._e2e_try(name, data, state)
        if status not in ("ok", "skipped"):
            return status, after, None
        sig = self.db.db.get_message_by_name(name).decode(bytes(data), scaling=False,
                                                          decode_choices=False)
        raw_t = int(sig["SensorTime"])
        if name == "Depth":
            dr, vr = int(sig["Depth"]), int(sig["Velocity"])
            if not (DEPTH_RAW[0] <= dr <= DEPTH_RAW[1] and VELOCITY_RAW[0] <= vr <= VELOCITY_RAW[1]):
                return "out_of_range", after, None
            return status, after, (raw_t, F32(F32(dr) * F32(0.001)), F32(F32(vr) * F32(0.01)))
        fr = int(sig["Force"])
        fault = int(sig.get("SensorFault", 0)) != 0
        if not fault and not FORCE_RAW[0] <= fr <= FORCE_RAW[1]:
            return "out_of_range", after, None   # flagged faulty: not checked (not used)
        return status, after, (raw_t, F32(F32(fr) * F32(0.0001)), F32(1.0 if fault else 0.0))

    def _newest(self, name: str) -> int | None:
        if name == "Depth":
            return self.depth[-1][0] if self.depth else None
        return self.last_force_t

    def _store(self, name: str, t: int, a: np.float32, b: np.float32) -> None:
        if name == "Depth":
            self.depth.append((t, a, b))
            if len(self.depth) > NODE["DEPTH_HISTORY"]:
                self.depth.pop(0)
            if self.depth_since_force is None:
                self.depth_since_force = t
        else:
            if len(self.forces) >= NODE["FORCE_QUEUE"]:
                self._count("queue_overflow")
                return
            self.last_force_t = t
            self.depth_since_force = None
            # a flagged sample's value is not read, nor watched
            self.forces.append((t, a, bool(b > F32(0.5)) or self._watch(a)))
        self._process()
        if name == "Depth":
            self._depth_predict()

    def _watch(self, force: np.float32) -> bool:
        """The node's nte_node_watch (nte_node.h SENSOR WATCH): the reading is not to be read
        -- at the Force frame's limit, or repeated STUCK_SAMPLES times while the needle moved
        STUCK_TRAVEL_UM in tissue; counted."""
        depth = self.depth[-1][1] if self.depth else F32(0.0)
        if self.watch_run > 0 and force == self.watch_force:
            self.watch_run += 1 if self.watch_run < NODE["STUCK_SAMPLES"] else 0
        else:
            self.watch_run, self.watch_force, self.watch_depth = 1, force, depth
        if abs(force) >= F32(FORCE_MAX_N):
            self._count("sensor_saturated")
            return True
        travel = F32(F32(NODE["STUCK_TRAVEL_UM"]) * F32(0.001))
        if (self.last.in_tissue and self.watch_run >= NODE["STUCK_SAMPLES"]
                and abs(F32(depth - self.watch_depth)) >= travel):
            self._count("sensor_stuck")
            return True
        return False

    def _resync(self, name: str, t: int) -> None:
        self._count("time_resync")
        if name == "Depth":
            self.depth_since_force = None   # a lost sensor is judged on the new timeline
        newest = self._newest(name)
        if newest is None or t > newest:
            return
        if name == "Depth":
            self.depth = []
        else:
            while self.forces:
                tf, f, _ = self.forces.pop(0)
                self._hold(tf, f)
            self.last_force_t = None

    def _on_sample(self, name: str, data: bytes) -> None:
        """The node's nte_node_on_sample: time rules with resynchronisation (nte_node.h)."""
        gap = self.resync_gap_us // TICK_US
        status, after, smp = self._decode_sample(name, data, self.rx.last.get(name))
        t = d = 0
        clk = (self.clock_raw, self.clock_ticks)
        if smp is not None:
            t, raw = self._unwrap(smp[0])
            clk = (raw, t)
            newest = self._newest(name)
            d = 1 if newest is None else t - newest
            if 0 < d <= gap:
                if self.pending[name] is not None:
                    self.pending[name] = None
                    self._count("time_jump_dropped")
                self._commit_e2e(name, after, status)
                self.clock_raw, self.clock_ticks = clk
                self._store(name, t, smp[1], smp[2])
                return
        p = self.pending[name]
        if p is not None:
            st_p, after_p, smp_p = self._decode_sample(name, data, p["after"])
            if smp_p is not None:
                t_p, raw_p = self._unwrap(smp_p[0], p["clock"])
                if 0 < t_p - p["t"] <= gap:
                    self.pending[name] = None
                    self._resync(name, p["t"])
                    self._commit_e2e(name, p["after"], p["status"])
                    self.clock_raw, self.clock_ticks = p["clock"]
                    self._store(name, p["t"], p["a"], p["b"])
                    self._commit_e2e(name, after_p, st_p)
                    self.clock_raw, self.clock_ticks = raw_p, t_p
                    self._store(name, t_p, smp_p[1], smp_p[2])
                    return
        if smp is None:
            if after is not None:
                self.rx.last[name] = after
            self._count(self._E2E_EVENT.get(status, "out_of_range"))
            return
        if -gap <= d <= 0:
            self._commit_e2e(name, after, status)
            self._count("time_backwards")
            return
        if p is not None:
            self._count("time_jump_dropped")
        self.pending[name] = {"t": t, "clock": clk, "after": after, "status": status,
                              "a": smp[1], "b": smp[2]}

    def _e2e(self, name: str, data: bytes) -> dict | None:
        """E2E check of a Command or Setting frame (a failure counted as the node counts it),
        then its raw signals; the caller calls _taken once their ranges hold (the node counts
        a skipped counter only for a frame it decoded whole: nte_node_decoded)."""
        status, _ = self.rx.check(name, data)
        self._last_e2e_status = status
        if status not in ("ok", "skipped"):
            self._count(self._E2E_EVENT[status])
            return None
        return self.db.db.get_message_by_name(name).decode(bytes(data), scaling=False,
                                                            decode_choices=False)

    def feed(self, can_id: int, data: bytes, extended: bool = False, remote: bool = False,
             t_us: int | None = None) -> None:
        """One frame as the node receives it; t_us = the node's port clock at reception (the
        command rate limit; the timestamps of nte-node's --received / --replay logs)."""
        name = None if (extended or remote) else self.db.name_of(can_id)
        if name == "Setting":
            if len(data) != FRAME_LENGTH:
                self._count("wrong_dlc")
                self.transfer.lost()
                return
            self._on_setting(bytes(data))
            return
        if name not in ("Depth", "Force", "Command"):
            self._count("unknown_id")
            return
        if len(data) != FRAME_LENGTH:
            self._count("wrong_dlc")
            return
        if name != "Command":
            self._on_sample(name, bytes(data))
            return
        sig = self._e2e(name, bytes(data))
        if sig is None:
            return
        self._on_command(sig, t_us)

    def _taken(self) -> None:
        if self._last_e2e_status == "skipped":
            self._count("counter_skipped")

    def _on_setting(self, data: bytes) -> None:
        """A Setting frame: its checks counted as the node counts them, then the transfer's
        rules (host_bench.setting_transfer)."""
        sig = self._e2e("Setting", data)
        if sig is not None and not self.transfer.frame_ok(int(sig["Item"]), float(sig["Value"])):
            self._count("out_of_range")
            sig = None
        if sig is None:
            self.transfer.lost()
            return
        self._taken()
        if not self.transfer.take(int(sig["Item"]), float(sig["Value"]),
                                  self._last_e2e_status == "skipped", bool(self.last.in_tissue)):
            self._count("setting_refused")

    def _on_command(self, sig: dict, t_us: int | None) -> None:
        """The node's command rules (nte_node.h, COMMANDS): applied entirely or not at all."""
        if not (0 <= int(sig["ModelSel"]) <= 3
                and all(0 <= int(sig.get(k, 0)) <= 2
                        for k in ("EstimatorSel", "AdaptCmd", "ForceSource"))):
            self._count("out_of_range")
            return
        self._taken()
        if self._last_e2e_status == "skipped":
            self._count("command_stale")
            return
        now = 0 if t_us is None else t_us
        if self.last_command_us is not None and now - self.last_command_us < self.command_interval_us:
            self._count("command_rate_limited")
            return
        model, estimator = self.model, self.estimator
        if int(sig["ModelSel"]):
            model = int(sig["ModelSel"])
        if int(sig["EstimatorSel"]):
            estimator = "robust" if int(sig["EstimatorSel"]) == 2 else "bank"
        restart = (model, estimator) != (self.model, self.estimator)
        if (((restart or int(sig["Reset"])) and (self.last.in_tissue or self.transfer.unapplied))
                or (restart and model == 3 and estimator == "robust")):   # nte_init refuses it
            self._count("command_refused")
            return
        if restart:
            self._start(model, estimator)
        if int(sig["AdaptCmd"]):
            # accepted in tissue; after the restart: the new estimator's parameters are held
            self.bank.set_frozen(int(sig["AdaptCmd"]) == 1)
        source = int(sig.get("ForceSource", 0))
        if source:
            # accepted in tissue: a failing sensor is bridged mid-insertion (nte_node.h)
            self.force_cmd_model = source == 2
        if int(sig["Reset"]):
            self.bank.reset()
            self.stepped = False
            self.last = EstimateOut(0, 0, 0, 0, 1, 0, 0, 0)
            self.last_vals = (0.0, 0.0, 0.0)
            self.contact_last = None
            self.health_last = None
        self.last_command_us = now

    def feed_all(self, frames: Iterable) -> "NodeMirror":
        for m in frames:
            self.feed(m.arbitration_id, bytes(m.data), m.is_extended_id, m.is_remote_frame,
                      int(round(m.timestamp * 1e6)))
        return self
