"""The node's output frames as raw signal values: what the node mirror (node_mirror.py) expects
and what a bus capture holds, read back with the DBC and compared frame by frame.

One record per frame: Estimate, Params, Contact (Model III) and Health (every model; the
robust refinement and the bank's per-filter fault words, nte_node.h HEALTH).  Raw values, not
physical ones, so that "the node's frames match the mirror's" means bit for bit.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Iterator, Protocol

import numpy as np

from reference_py.bus.dbc import PARAM_SIGNALS, NteDatabase

F32 = np.float32


@dataclass
class EstimateOut:
    force_raw: int
    innovation_raw: int
    z_raw: int
    in_tissue: int
    adapting: int
    saturated: int
    fault: int
    stale: int

    def key(self) -> tuple[int, ...]:
        return (self.force_raw, self.innovation_raw, self.z_raw, self.in_tissue, self.adapting,
                self.saturated, self.fault, self.stale)


@dataclass
class ParamOut:
    index: int
    value: np.float32
    std_raw: int


@dataclass
class ContactOut:
    contact_state: int
    surface_valid: int
    active_model: int
    surface_raw: int
    tare_raw: int
    layer: int = 0

    def key(self) -> tuple[int, ...]:
        return (self.contact_state, self.surface_valid, self.active_model, self.surface_raw,
                self.tare_raw, self.layer)


@dataclass
class HealthOut:
    refined: int
    converged: int
    confidence_raw: int
    filter_flags: tuple[int, int, int]
    refining: int = 0

    def key(self) -> tuple[int, ...]:
        return (self.refined, self.converged, self.confidence_raw, *self.filter_flags,
                self.refining)


class MirrorOutputs(Protocol):
    """What compare() reads of a mirror: its expected frames, in order."""
    estimates: list[EstimateOut]
    params: list[ParamOut]
    contacts: list[ContactOut]
    healths: list[HealthOut]


def _outputs_raw(db: NteDatabase, messages: Iterable, names: tuple[str, ...],
                 bad: list[int]) -> Iterator[tuple[str, dict]]:
    """(name, raw signal values) of the node's frames of the given messages, in order; a frame
    that fails its E2E check is counted in bad[0] and skipped."""
    rx = db.receiver()
    for m in messages:
        name, sig, _ = rx.decode(m.arbitration_id, bytes(m.data))
        if name not in names:
            continue
        if sig is None:
            bad[0] += 1
            continue
        yield name, db.db.get_message_by_name(name).decode(bytes(m.data), scaling=False,
                                                           decode_choices=False)


def node_outputs(db: NteDatabase, messages: Iterable) -> tuple[list[EstimateOut], list[ParamOut], int]:
    """The node's Estimate and Params frames (in order) as raw values; and the count of output
    frames that failed their E2E check."""
    est: list[EstimateOut] = []
    par: list[ParamOut] = []
    bad = [0]
    for name, raw in _outputs_raw(db, messages, ("Estimate", "Params"), bad):
        if name == "Estimate":
            est.append(EstimateOut(int(raw["ForceEst"]), int(raw["Innovation"]), int(raw["Z"]),
                                   int(raw["InTissue"]), int(raw["Adapting"]),
                                   int(raw["Saturated"]), int(raw["Fault"]), int(raw["Stale"])))
        else:
            j = int(raw["ParamIndex"])
            vname, sname = PARAM_SIGNALS[j]
            par.append(ParamOut(j, F32(raw[vname]), int(raw[sname])))
    return est, par, bad[0]


def contact_outputs(db: NteDatabase, messages: Iterable) -> tuple[list[ContactOut], int]:
    """The node's Contact frames (in order) as raw values; and how many failed E2E."""
    bad = [0]
    out = [ContactOut(int(raw["ContactState"]), int(raw["SurfaceValid"]), int(raw["ActiveModel"]),
                      int(raw["Surface"]), int(raw["Tare"]), int(raw["Layer"]))
           for _, raw in _outputs_raw(db, messages, ("Contact",), bad)]
    return out, bad[0]


def health_outputs(db: NteDatabase, messages: Iterable) -> tuple[list[HealthOut], int]:
    """The node's Health frames (in order) as raw values; and how many failed E2E."""
    bad = [0]
    out = [HealthOut(int(raw["Refined"]), int(raw["Converged"]), int(raw["Confidence"]),
                     (int(raw["Filter0Flags"]), int(raw["Filter1Flags"]),
                      int(raw["Filter2Flags"])), int(raw["Refining"]))
           for _, raw in _outputs_raw(db, messages, ("Health",), bad)]
    return out, bad[0]


def compare(mirror: MirrorOutputs, est: list[EstimateOut], par: list[ParamOut],
            contacts: list[ContactOut] | None = None,
            healths: list[HealthOut] | None = None) -> dict:
    """Mismatch counts between the node's outputs and the mirror's (the Contact and Health
    frames too when ``contacts`` / ``healths``, the node's, are given)."""
    n = min(len(est), len(mirror.estimates))
    est_mis = sum(1 for a, b in zip(est, mirror.estimates) if a.key() != b.key())
    m = min(len(par), len(mirror.params))
    val_mis = sum(1 for a, b in zip(par, mirror.params)
                  if a.index != b.index or a.value.tobytes() != b.value.tobytes())
    std_mis = sum(1 for a, b in zip(par, mirror.params) if a.std_raw != b.std_raw)
    std_off1 = sum(1 for a, b in zip(par, mirror.params) if abs(a.std_raw - b.std_raw) > 1)
    first = next((i for i, (a, b) in enumerate(zip(est, mirror.estimates)) if a.key() != b.key()),
                 None)
    return {"estimates_node": len(est), "estimates_reference": len(mirror.estimates),
            "estimates_compared": n, "estimate_mismatches": est_mis,
            "first_mismatch": first,
            "params_node": len(par), "params_reference": len(mirror.params),
            "param_value_mismatches": val_mis, "param_std_mismatches": std_mis,
            "param_std_beyond_1lsb": std_off1,
            "stale_reference": sum(e.stale for e in mirror.estimates),
            "stale_node": sum(e.stale for e in est),
            **({} if contacts is None else {
                "contact_node": len(contacts), "contact_reference": len(mirror.contacts),
                "contact_mismatches": sum(1 for a, b in zip(contacts, mirror.contacts)
                                          if a.key() != b.key())}),
            **({} if healths is None else {
                "health_node": len(healths), "health_reference": len(mirror.healths),
                "health_mismatches": sum(1 for a, b in zip(healths, mirror.healths)
                                         if a.key() != b.key())})}
