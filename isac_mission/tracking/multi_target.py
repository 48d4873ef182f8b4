"""The multi-target tracker (docs/model.md, "The multi-target tracker"): one EKF per track,
each UAV's unlabelled report associated to the tracks (JPDA or GNN, tracking/association.py),
tracks started from what no track explains (tracking/initiation.py), confirmed and deleted by
rules on their hits, with IDs that never change or repeat.

A slot: every track is predicted (eq. 3); then the UAVs' reports are taken one after another
(the sequential multi-sensor JPDA: UAV m's report meets the tracks as UAV m - 1's left them).
For a report, each track i has the predicted measurement h_m(x_i) and the innovation covariance
S = H P H^T + R at its prediction, the detection probability of the scenario's model at that
range, and the clutter density lambda; association gives the marginals beta_ij (JPDA) or one
measurement per track (GNN, a one-hot beta), and the PDA update folds them in. A measurement
the tracks do not explain (their marginals of it sum below EXPLAINED) goes to initiation, with
the other UAVs' unexplained measurements of the slot.

Track management, per slot: the track's association weight w = sum_m (1 - beta_m0) (the
expected number of UAVs that measured it); a hit is w >= `hit_weight`. What initiation finds is
first a candidate, internal to the tracker: three UAVs' measurements leave a fit with two degrees
of freedom, which clutter passes often (about one candidate a slot from 15 false alarms over five
UAVs), so a candidate becomes a tentative track, with its ID, only when the next slot is a hit,
and is dropped silently otherwise. A tentative track is confirmed at `confirm_hits` hits within
its first `confirm_window` slots (its candidate slot counts as one) and deleted when that can no
longer happen; a confirmed track is deleted after `delete_after_misses` slots in a row without a
hit. A candidate whose position lies inside an older track's gate (a second track on one
target) is dropped.

A ghost: where most UAVs' ranges are coarse, a track can start on a wrong minimum of its fit and
keep taking the target's coarse measurements, while a UAV with a fine range sees the target's
echo outside the track's gate. A report that misses a track but holds an unexplained
measurement whose Doppler fits the track's prediction is a suspect; the track's own
measurements of the slot with the suspect are fitted, and a passing fit outside the track's gate
refutes the track. Two refutations in a row that agree move the track there, its ID kept; a
refuted slot is no hit for a track not yet confirmed, so a ghost is not confirmed before its
repair.

With the IMM (`TrackerSettings.imm`, tracker.motion imm; tracking/imm.py): each track carries
its modes, its belief their 4-D moment-matched marginal; a report's association row of the track
comes from the mixture of its modes (`mode_rows`), each mode takes the PDA update with those
marginals and its likelihood of the report, and the mode probabilities follow after the slot's
reports; the track's bound takes the modes' noise mixed by their predicted probabilities.

A restart: `saved` gives what the tracker carries from a slot to the next (`TrackerState`,
written to a live trace's slot line: records/tracks.py), and `restored` makes a tracker
that goes on from it exactly (`serve --resume`).

Pure: numpy and scipy. Shapes: M UAVs, T tracks, k_m measurements of UAV m.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np

from isac_mission.config.targets import DetectionSpec
from isac_mission.model.detections import detection_probability
from isac_mission.model.motion import ConstantVelocity
from isac_mission.model.radar import SensingParams, measure, measurement_jacobian
from isac_mission.tracking.association import (
    MISSED,
    Hypotheses,
    gate_threshold,
    gnn,
    jpda,
    pda_update,
)
from isac_mission.tracking.ekf import ekf_predict
from isac_mission.tracking.imm import (
    ImmBelief,
    ImmModel,
    ImmPath,
    ModePredictions,
    imm_model,
    imm_predict,
    imm_start,
    mixed_kappa,
    mode_pda_updates,
    mode_predictions,
    mode_rows,
    with_likelihoods,
)
from isac_mission.tracking.initiation import InitiationSettings, initiate, outside_gate, refit
from isac_mission.tracking.origin_uncertainty import (
    bound_step_with_origin,
    uav_reduction_factors,
)
from isac_mission.tracking.pcrb import Bound, predict_information
from isac_mission.tracking.tracker import SlotTracking, TrackEstimate, TrackPrediction
from isac_mission.types import BoolArray, FloatArray, Gaussian

if TYPE_CHECKING:
    from isac_mission.config import Scenario

Associator = Literal["jpda", "gnn"]

EXPLAINED = 0.5
"""A measurement whose association probabilities to the tracks sum to this or more is the
tracks'; the others go to initiation (a new target's measurement that falls in a broad gate of
a track, a UAV's coarse range, is not lost to it)."""

_MIN_CLUTTER_DENSITY = 1e-12
"""lambda per m * (m/s) that association uses when the scenario has no false alarms (its
likelihood ratios divide by lambda): every gated measurement is then the track's by far."""


@dataclass(frozen=True)
class TrackerSettings:
    """The tracker's constants.

    F, W [4, 4]: eq. 3's transition and the tracks' process noise (the filter's);
    bound_W [4, 4] or None: the process noise of each track's bound (the targets' own, eq. 4;
    None: W); detection: the scenario's detection model
    (its P_d, or the SNR model's threshold) and clutter_density lambda (per m * m/s);
    association: "jpda" or "gnn"; gate_prob: P_g of the association gate; hit_weight,
    confirm_hits, confirm_window, delete_after_misses: track management (module docstring);
    initiation: tracking/initiation.py's settings; imm: the interacting multiple model every
    track's filter runs (tracking/imm.py; None: the EKF with F and W).
    """

    F: FloatArray
    W: FloatArray
    detection: DetectionSpec
    clutter_density: float
    association: Associator = "jpda"
    gate_prob: float = 0.99
    hit_weight: float = 2.5
    confirm_hits: int = 3
    confirm_window: int = 4
    delete_after_misses: int = 3
    initiation: InitiationSettings = field(default_factory=InitiationSettings)
    bound_W: FloatArray | None = None
    imm: ImmModel | None = None

    @property
    def bound_noise(self) -> FloatArray:
        """The bound's process noise [4, 4]."""
        return self.W if self.bound_W is None else self.bound_W

    @classmethod
    def from_scenario(cls, s: Scenario) -> TrackerSettings:
        """The settings of a scenario's `tracker.multi:` and `detection:` sections."""
        c = s.multi_tracker
        kappa = s.kappa if c.process_noise_intensity is None else c.process_noise_intensity
        detection = s.detection
        if detection is None:
            raise ValueError("the multi-target tracker needs the scenario's detection model")
        return cls(
            F=s.motion.transition(s.dt),
            W=ConstantVelocity(kappa).process_noise(s.dt),
            bound_W=s.motion.process_noise(s.dt),
            detection=detection,
            clutter_density=detection.clutter_density,
            association=c.association,
            gate_prob=c.gate_prob,
            hit_weight=c.hit_weight,
            confirm_hits=c.confirm_hits,
            confirm_window=c.confirm_window,
            delete_after_misses=c.delete_after_misses,
            initiation=InitiationSettings(
                gate_prob=c.initiation_gate_prob,
                max_position_std_m=c.max_initial_position_std_m,
                max_speed_mps=c.max_target_speed_mps,
                detection=detection,
                area_m=(float(s.area[0]), float(s.area[1])),
            ),
            imm=None if s.imm is None else imm_model(s.imm, s.dt),
        )


@dataclass(frozen=True)
class SavedTrack:
    """One track as it goes from one slot to the next (what `MultiTargetTracker.saved` keeps):
    track_id, confirmed, belief (x [4], P [4, 4]), information J [4, 4] of its bound, hits: its
    hits within its first `confirm_window` slots (what confirmation counts), misses_in_row: the
    slots in a row without a hit (what deletion counts), refuted: a refutation a UAV made this
    slot, waiting for the next slot's to agree (module docstring, "A ghost"; None: none),
    modes: the IMM's modes of the track (None: the EKF's track)."""

    track_id: int
    confirmed: bool
    belief: Gaussian
    information: FloatArray
    hits: tuple[bool, ...]
    misses_in_row: int
    refuted: Gaussian | None = None
    modes: ImmBelief | None = None


@dataclass(frozen=True)
class TrackerState:
    """Everything the tracker carries from one slot's update to the next slot's predict:
    tracks (tentative and confirmed, in the tracker's order), candidates (the internal ones,
    negative IDs, each a belief whose bound is its covariance: started this slot), next_id: the
    ID the next new track gets (IDs never repeat). A restart continues from it exactly
    (`MultiTargetTracker.restored`)."""

    tracks: tuple[SavedTrack, ...]
    candidates: tuple[Gaussian, ...]
    next_id: int


@dataclass
class _Track:
    track_id: int
    belief: Gaussian
    bound: Bound
    confirmed: bool
    hits: list[bool]
    misses_in_row: int = 0
    x_pred: FloatArray | None = None
    J_pred: FloatArray | None = None
    own: dict[int, FloatArray] = field(default_factory=dict)
    suspects: list[tuple[int, FloatArray]] = field(default_factory=list)
    refuted: Gaussian | None = None
    refuted_now: bool = False
    modes: ImmBelief | None = None
    """The IMM's modes (settings.imm; belief is then their 4-D moment-matched marginal)."""
    log_likelihoods: FloatArray | None = None
    """The IMM's modes' log-likelihoods of the slot's reports so far."""
    bound_W: FloatArray | None = None
    """The process noise [4, 4] of the bound's step this slot (`_bound_noise` at predict)."""


class MultiTargetTracker:
    """Tracks from unlabelled reports: `add_confirmed` for a target whose prior is known, then
    `predict` and `update` each slot."""

    labels_reports = False

    def __init__(self, settings: TrackerSettings) -> None:
        self.settings = settings
        self._tracks: list[_Track] = []
        self._next_id = 1
        self._next_candidate = 1
        self._gate = gate_threshold(settings.gate_prob)

    @classmethod
    def restored(cls, settings: TrackerSettings, state: TrackerState) -> MultiTargetTracker:
        """The tracker as it was when `saved` gave `state` (after a slot's update): the same
        tracks in the same order, with their IDs, beliefs, bounds, hits and refutations, the
        same candidates, and the same next ID; it goes on exactly as that tracker would.
        ValueError for IDs that are not positive, repeat, or are not below next_id."""
        ids = [t.track_id for t in state.tracks]
        if any(i <= 0 for i in ids) or len(set(ids)) != len(ids):
            raise ValueError(f"track IDs must be positive and distinct, got {ids}")
        if ids and max(ids) >= state.next_id:
            raise ValueError(f"next track ID {state.next_id} is not above the IDs {ids}")
        tracker = cls(settings)
        for t in state.tracks:
            refuted = None if t.refuted is None else _copied(t.refuted)
            tracker._tracks.append(
                _Track(
                    t.track_id,
                    _copied(t.belief),
                    Bound.from_information(np.array(t.information, dtype=np.float64)),
                    t.confirmed,
                    hits=list(t.hits),
                    misses_in_row=t.misses_in_row,
                    refuted=refuted,
                    modes=t.modes,
                )
            )
        for belief in state.candidates:
            tracker._start(_copied(belief), confirmed=False, candidate=True)
        tracker._next_id = state.next_id
        return tracker

    def saved(self) -> TrackerState:
        """What the tracker carries to the next slot (call after `update`): `restored` gives
        it back."""
        window = self.settings.confirm_window
        tracks = tuple(
            SavedTrack(
                t.track_id,
                t.confirmed,
                _copied(t.belief),
                t.bound.J.copy(),
                tuple(t.hits[:window]),
                t.misses_in_row,
                None if t.refuted is None else _copied(t.refuted),
                t.modes,
            )
            for t in self._tracks
            if t.track_id > 0
        )
        # The candidates are last in the tracker's order: started after the slot's management.
        candidates = tuple(_copied(t.belief) for t in self._tracks if t.track_id < 0)
        return TrackerState(tracks, candidates, self._next_id)

    def add_confirmed(self, belief: Gaussian) -> int:
        """Start a confirmed track from a known prior (its bound from the same covariance);
        returns its ID."""
        return self._start(belief, confirmed=True)

    def _start(self, belief: Gaussian, confirmed: bool, candidate: bool = False) -> int:
        if candidate:  # an internal, negative ID until its second hit
            track_id = -self._next_candidate
            self._next_candidate += 1
        else:
            track_id = self._new_id()
        bound = Bound.from_covariance(belief.P.copy())
        track = _Track(track_id, belief, bound, confirmed, hits=[True])
        imm = self.settings.imm
        if imm is not None:
            track.modes = imm_start(imm, belief)
            track.belief = track.modes.marginal()
        self._tracks.append(track)
        return track_id

    def _new_id(self) -> int:
        self._next_id += 1
        return self._next_id - 1

    def predict(self) -> tuple[TrackPrediction, ...]:
        """Advance every track and its bound one slot (eq. 3); returns the predictions of the
        tentative and confirmed tracks (candidates are internal)."""
        s = self.settings
        out = []
        for t in self._tracks:
            if s.imm is not None and t.modes is not None:
                t.modes = imm_predict(s.imm, t.modes)
                t.belief = t.modes.marginal()
                t.log_likelihoods = np.zeros(len(s.imm.modes))
            else:
                t.belief = ekf_predict(t.belief, s.F, s.W)
            t.x_pred = t.belief.x.copy()
            t.bound_W = self._bound_noise(t)
            t.J_pred = predict_information(t.bound, s.F, t.bound_W)
            t.own, t.suspects, t.refuted_now = {}, [], False
            if t.refuted is not None:
                t.refuted = ekf_predict(t.refuted, s.F, s.W)
            if t.track_id > 0:
                existence = 1.0 if t.confirmed else min(1.0, sum(t.hits) / s.confirm_hits)
                path = None if s.imm is None or t.modes is None else ImmPath(s.imm, t.modes)
                out.append(
                    TrackPrediction(
                        t.track_id, t.confirmed, t.belief, t.J_pred, existence, manoeuvre=path
                    )
                )
        return tuple(out)

    def update(
        self,
        reports: Sequence[FloatArray],
        uav_xy_m: FloatArray,
        eta: FloatArray,
        sensing: SensingParams,
    ) -> SlotTracking:
        """Fold in one slot's reports [M] (arrays [k_m, 2] of range m and Doppler m/s, no
        labels) taken at uav_xy_m [M, 2] with shares eta [M]; step each track's bound; manage
        the tracks. Call after `predict`. `sensing` gives eq. 8's variances (its radar gain the
        nominal target's: the tracker does not know an unknown target's RCS)."""
        weights = np.zeros(len(self._tracks))
        unexplained: list[FloatArray] = []
        for m, report in enumerate(reports):
            z = np.asarray(report, dtype=float).reshape(-1, 2)
            if not eta[m] > 0:
                unexplained.append(np.zeros((0, 2)))
                continue
            explained = self._associate(m, z, uav_xy_m[m], float(eta[m]), sensing, weights)
            unexplained.append(z[~explained])
        for t in self._tracks:
            if t.modes is not None and t.log_likelihoods is not None:
                t.modes = with_likelihoods(t.modes, t.log_likelihoods)
                t.belief, t.log_likelihoods = t.modes.marginal(), None
        self._repair(unexplained, uav_xy_m, eta, sensing)
        for t in self._tracks:
            self._step_bound(t, uav_xy_m, eta, sensing)
        weight_of = {id(t): float(w) for t, w in zip(self._tracks, weights, strict=True)}
        deleted, started = self._manage(weights)
        candidates = {
            self._start(b, confirmed=False, candidate=True)
            for b in initiate(unexplained, uav_xy_m, eta, sensing, self.settings.initiation)
        }
        self._drop_duplicates(candidates)
        out = tuple(
            TrackEstimate(t.track_id, t.confirmed, t.belief, t.bound, weight_of.get(id(t), 0.0))
            for t in self._tracks
            if t.track_id > 0
        )
        return SlotTracking(out, tuple(started), tuple(deleted))

    def _associate(
        self,
        m: int,
        z: FloatArray,
        uav_xy: FloatArray,
        eta: float,
        sensing: SensingParams,
        weights: FloatArray,
    ) -> BoolArray:
        """One UAV's report against every track: PDA updates in place, association weights
        added to weights [T]; returns [k] whether each measurement is explained (the tracks'
        marginals of it sum to EXPLAINED or more; under GNN, it was assigned)."""
        s = self.settings
        T = len(self._tracks)
        q = uav_xy[None]
        if T == 0:
            return np.zeros(len(z), dtype=bool)
        z_hat = np.empty((T, 2))
        H = np.empty((T, 2, 4))
        S = np.empty((T, 2, 2))
        for i, t in enumerate(self._tracks):
            z_hat[i] = measure(t.belief.x, q)
            H[i] = measurement_jacobian(t.belief.x, q)
            R = np.diag(sensing.variances(z_hat[i, :1], np.array([eta])))
            S[i] = H[i] @ t.belief.P @ H[i].T + R
        pd = detection_probability(
            z_hat[:, 0], np.full(T, sensing.radar_gain), s.detection, sensing.B, sensing.Ts
        )
        if len(z) == 0:
            return np.zeros(0, dtype=bool)
        density = max(s.clutter_density, _MIN_CLUTTER_DENSITY)
        h = Hypotheses.of(z_hat, S, z, pd, density, self._gate, s.gate_prob)
        predicted: dict[int, ModePredictions] = {}
        for i, t in enumerate(self._tracks):
            if t.modes is not None:
                r_pair = sensing.variances(z_hat[i, :1], np.array([eta]))
                predicted[i] = mode_predictions(t.modes, uav_xy, r_pair)
                row = mode_rows(
                    t.modes, z, uav_xy, r_pair, float(pd[i]), density, self._gate, predicted[i]
                )
                row.put(h, i)
        if s.association == "jpda":
            beta = jpda(h)
        else:
            choice = gnn(h)
            beta = np.zeros((T, len(z) + 1))
            beta[np.arange(T), np.where(choice == MISSED, len(z), choice)] = 1.0
        doppler_gate = gate_threshold(s.initiation.gate_prob, 1)
        for i, t in enumerate(self._tracks):
            best = int(np.argmax(beta[i, :-1]))
            if beta[i, best] >= EXPLAINED:
                t.own[m] = z[best]
            elif beta[i, -1] >= EXPLAINED:
                # Missed here: a measurement whose Doppler fits but whose range does not may be
                # this target's, seen by a UAV whose range refutes where the track is.
                nu_v = z[:, 1] - z_hat[i, 1]
                t.suspects += [
                    (m, z[j]) for j in np.flatnonzero(nu_v**2 <= doppler_gate * S[i, 1, 1])
                ]
            if beta[i, -1] >= 1.0:
                continue  # nothing of this report is the track's: its prediction stands
            if t.modes is not None:
                # Each mode takes the report with the marginals of the mixed prediction.
                r_pair = sensing.variances(z_hat[i, :1], np.array([eta]))
                t.modes, log_lik = mode_pda_updates(
                    t.modes,
                    z,
                    uav_xy,
                    r_pair,
                    beta[i],
                    float(pd[i]),
                    density,
                    s.gate_prob,
                    predicted[i],
                )
                before = 0.0 if t.log_likelihoods is None else t.log_likelihoods
                t.log_likelihoods = before + log_lik
                t.belief = t.modes.marginal()
            else:
                x, P = pda_update(t.belief.x, t.belief.P, z_hat[i], H[i], S[i], z, beta[i])
                t.belief = Gaussian(x=x, P=P)
            weights[i] += 1.0 - beta[i, -1]
        return np.asarray(beta[:, :-1].sum(axis=0) >= EXPLAINED, dtype=bool)

    def _repair(
        self,
        unexplained: list[FloatArray],
        uav_xy_m: FloatArray,
        eta: FloatArray,
        sensing: SensingParams,
    ) -> list[int]:
        """Re-fit each track that a UAV refuted two slots running (module docstring, "A
        ghost"): the track's own measurements of the slot with one of that UAV's unexplained
        suspects, fitted; a fit that passes initiation's tests and lies outside the track's gate
        is a refutation. A refutation that the last slot's, predicted, agrees with moves the
        track there (the suspect is then the track's); a single one is kept for the next slot.
        Returns the IDs moved."""
        s = self.settings.initiation
        repaired = []
        for t in self._tracks:
            refuted = None
            if len(t.own) + 1 >= s.min_uavs:
                for m, z in t.suspects:
                    row = np.flatnonzero(np.all(unexplained[m] == z, axis=1))
                    if not len(row):
                        continue
                    belief = refit({**t.own, m: z}, t.belief.x, uav_xy_m, eta, sensing, s)
                    if belief is not None and outside_gate(t.belief, belief, self._gate):
                        refuted = belief, m, int(row[0])
                        break
            if refuted is None:
                t.refuted = None
                continue
            belief, m, row_index = refuted
            t.refuted_now = True
            if t.refuted is not None and not outside_gate(t.refuted, belief, self._gate):
                t.belief, t.refuted = belief, None
                if self.settings.imm is not None:  # the modes start again where the fit is
                    t.modes = imm_start(self.settings.imm, belief)
                unexplained[m] = np.delete(unexplained[m], row_index, axis=0)
                repaired.append(t.track_id)
            else:
                t.refuted = belief
        return repaired

    def _step_bound(
        self, t: _Track, uav_xy_m: FloatArray, eta: FloatArray, sensing: SensingParams
    ) -> None:
        """The track's bound takes the slot's step at its predicted state (where eq. 12 is
        evaluated), each UAV's information scaled by its reduction factor q_m of P_d and the
        clutter (tracking/origin_uncertainty.py); a UAV without a share adds nothing."""
        if t.x_pred is None:
            return  # started this slot: its bound is its initial covariance
        s = self.settings
        range_m = np.linalg.norm(t.x_pred[None, :2] - uav_xy_m, axis=1)
        sensed = np.asarray(eta, dtype=float) > 0
        with np.errstate(divide="ignore"):
            r_diag = sensing.variances(range_m, np.where(sensed, eta, 0.0))
        r_diag[~np.concatenate([sensed, sensed])] = np.nan
        pd = detection_probability(
            range_m, np.full(len(range_m), sensing.radar_gain), s.detection, sensing.B, sensing.Ts
        )
        q = uav_reduction_factors(pd, s.clutter_density, r_diag, self._gate)
        W = s.bound_noise if t.bound_W is None else t.bound_W
        t.bound = bound_step_with_origin(t.bound, s.F, W, t.x_pred, uav_xy_m, r_diag, q)

    def _bound_noise(self, t: _Track) -> FloatArray:
        """The process noise of the track's bound for the slot it is predicted to [4, 4]: the
        settings' (the targets' own), or with the IMM its modes' white noise mixed by their
        predicted probabilities (call after the modes' prediction),
        W(sum_j c_j kappa_j) (docs/model.md, "The interacting multiple model")."""
        imm = self.settings.imm
        if imm is None or t.modes is None:
            return self.settings.bound_noise
        return ConstantVelocity(mixed_kappa(imm, t.modes.probabilities)).process_noise(imm.dt_s)

    def _manage(self, weights: FloatArray) -> tuple[list[int], list[int]]:
        """Hits, promotion, confirmation and deletion after the slot's reports; returns the IDs
        deleted and those started (candidates promoted to tentative tracks)."""
        s = self.settings
        keep: list[_Track] = []
        deleted: list[int] = []
        started: list[int] = []
        for t, w in zip(self._tracks, weights, strict=True):
            # A refuted slot is no hit for a track not yet confirmed: a ghost waits for its repair.
            hit = bool(w >= s.hit_weight) and (t.confirmed or not t.refuted_now)
            t.hits.append(hit)
            t.misses_in_row = 0 if hit else t.misses_in_row + 1
            if t.track_id < 0:
                if not hit:
                    continue  # a candidate not seen again: gone without a trace
                t.track_id = self._new_id()
                started.append(t.track_id)
            if not t.confirmed:
                window = t.hits[: s.confirm_window]
                if sum(window) >= s.confirm_hits:
                    t.confirmed = True
                elif sum(window) + max(s.confirm_window - len(window), 0) < s.confirm_hits:
                    deleted.append(t.track_id)
                    continue
            elif t.misses_in_row >= s.delete_after_misses:
                deleted.append(t.track_id)
                continue
            keep.append(t)
        self._tracks = keep
        return deleted, started

    def _drop_duplicates(self, new: set[int]) -> None:
        """Drop the new candidates whose position lies in an older track's position gate."""
        old = [t for t in self._tracks if t.track_id not in new]
        deleted = [
            t.track_id
            for t in self._tracks
            if t.track_id in new
            and any(not outside_gate(o.belief, t.belief, self._gate) for o in old)
        ]
        self._tracks = [t for t in self._tracks if t.track_id not in deleted]


def _copied(g: Gaussian) -> Gaussian:
    """A belief with arrays of its own (writable float64)."""
    return Gaussian(x=np.array(g.x, dtype=np.float64), P=np.array(g.P, dtype=np.float64))
