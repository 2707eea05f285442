"""EKF-SLAM map management: candidates, augmentation (eqs. 38-48), pruning, eviction.

Tentative landmarks (ghost protection)
--------------------------------------
An observation that no map landmark explains starts a *candidate* that lives OUTSIDE the
state, in a list with its own world position and 2 x 2 covariance (the observation put in
the map frame with the current pose, ``G_r P_rr G_r^T + G_z R G_z^T``, fused with later
hits by the information form). Later observations that no landmark explains are matched to
candidates with a Mahalanobis gate (greedy nearest, one hit per candidate per scan). A
candidate created at scan ``s0`` that collects ``confirm_hits`` hits (its first observation
included) before scan ``s0 + confirm_window`` is confirmed: the observation of the
confirming scan is augmented into the state with eqs. 38-48, so the state only ever sees
that one observation and its correct correlations; the earlier hits only decided that the
corner is real (their information is discarded rather than double counted, which keeps the
filter consistent). Candidates that do not reach the count within the window are dropped.
Candidates never update the robot pose.

Map management
--------------
Tentative landmarks (above) keep one-off clutter out of the state. A landmark that did
enter it and then disappears (a moved cart, a person, a ghost corner of mixed pixels) is
removed by visibility-aware pruning (:mod:`.visibility`): a scan whose beams pass through
the landmark's place (in view, facing, not occluded, every beam near it returning from
beyond it) is a *miss*; a detection (or an observation inside the
``new_landmark_probability`` gate, ambiguous or grazing) resets the count; after
``prune_misses`` consecutive misses (default ``confirm_hits``) the landmark is
marginalised out (its rows and columns dropped). A detector failure with a return at the
landmark is no miss: on the simulated office no landmark is pruned. Map size:
``max_landmarks`` is a budget; with ``map_full='evict'`` (default) a confirmed landmark
that finds the map full replaces the least recently seen one (ties: fewest detections)
that was not seen in this scan, so mapping never stops in a new area; ``'reject'`` keeps
the former behaviour (reason ``'cap'``).

Establishment (off by default, ``establish_hits > 0``): a corner that entered the state is
*provisional* until it is detected again, as a candidate is confirmed by hits:
``establish_hits`` detections after the one that confirmed it, counted in the scans that
gave it a chance
(:func:`.visibility.corners_in_view`: in view and range, facing, no return in front of it,
no farther than it was ever detected). A provisional corner whose chances reach
``establish_chances`` (default ``confirm_window``) with fewer detections is removed
(marginalised, ``stats['retired']``): the N-of-M rule of the candidates, counted in
opportunities instead of scans, so a corner the robot drove away from stays provisional
(and in the map) rather than being retired unseen. It aims at what the two other rules let
through: corners of clutter confirmed by three views from nearly one place and never again
detected from elsewhere, although their place stays in view and returns there (so no miss
is counted). An ambiguous or grazing observation near it is neither a chance nor a
detection. Lines are not affected (their chance would need the extent test). Why it is off:
on the CMU Wean logs (1 deg beams) real wall corners (door jambs) are as often not
detected again from other viewpoints as clutter is, and with ``establish_hits =
confirm_hits`` the share of corners within 10 cm of a wall of the building's grid fell
on two of the three logs (robotdata1 0.77 -> 0.70, robotdata5 0.62 -> 0.51, robotdata2
0.47 -> 0.58 with its scans 0.563 -> 0.540 near a wall; 16-18 corners retired per log;
``benchmarks/bench_slam_real.py wean --establish-hits 3``).
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Tuple

import numpy as np

from ._linalg import _wrap
from .association import icnn, mahalanobis_table
from .consistency import chi2_gate
from .line_landmarks import ends_to_map, extents_overlap, merge_extent, project_extent
from .observation_models import (_landmark_cols, feature_initialization, observation_model,
                                 predicted_observation_covariance)
from .slam_params import _FIRST_ESTIMATE_RULES, CORNER, LINE
from .visibility import corners_in_view, landmarks_missed, ScanGeometry


@dataclass
class _Candidate:
    """A tentative landmark outside the state (see the module docstring)."""

    cid: int
    xy: np.ndarray     # (2,) map-frame position estimate
    cov: np.ndarray    # (2, 2) its covariance
    first_scan: int
    hits: int
    bis: np.ndarray    # (2,) sum of unit vectors of the world bisectors (zeros: unknown)
    opening: float     # mean opening (nan: unknown)
    n_open: int        # observations averaged into ``opening``
    kind: int = CORNER
    ends: Optional[np.ndarray] = None  # (2, 2) map-frame extent of a line candidate
    max_seen: float = 0.0  # largest detection distance


def augment_map(x: np.ndarray, p: np.ndarray, z: np.ndarray, r: np.ndarray,
                kind: Optional[np.ndarray] = None, lever_from: Optional[np.ndarray] = None
                ) -> Tuple[np.ndarray, np.ndarray]:
    """Append landmarks initialised from observations to the state (eqs. 38-48).

    ``P* = Y [[P, 0], [0, R]] Y^T`` (eq. 43) with ``Y`` of eq. 44 evaluated block-wise: the
    new rows are ``G_r P_r.`` and the new diagonal ``G_r P_rr G_r^T + G_z R G_z^T``.

    Args:
        x: State.
        p: Covariance.
        z: (L, 2) observations of the new landmarks.
        r: (L, 2, 2) their covariances.
        kind: Optional (L,) kinds (None: corners).
        lever_from: Optional (2,) robot position the heading column of ``G_r`` takes its
            lever arm from (observability-constrained: the robot's prior position, so
            that ``G_r`` maps the robot's unobservable directions onto the new landmark's
            at its first estimate, :mod:`.consistent_linearisation`); None: the current
            estimate (eq. 46).

    Returns:
        ``(x*, P*)`` new arrays of size ``n + 2L``.
    """
    n, nl = x.size, z.shape[0]
    g, gr, gz = feature_initialization(x[:3], z, kind)
    if lever_from is not None:  # G_r N_r(prior) = N_new(g): no information on them
        line = np.zeros(nl, dtype=bool) if kind is None else np.asarray(kind) == LINE
        gr[~line, 0, 2] = -(g[~line, 1] - lever_from[1])
        gr[~line, 1, 2] = g[~line, 0] - lever_from[0]
        a = g[line, 1]
        gr[line, 0, 2] = -lever_from[0] * np.sin(a) + lever_from[1] * np.cos(a)
    gr2 = gr.reshape(2 * nl, 3)
    x_new = np.concatenate([x, g.reshape(-1)])  # eqs. 38-39, 41
    p_new = np.empty((n + 2 * nl, n + 2 * nl))
    p_new[:n, :n] = p
    cross = gr2 @ p[:3, :]  # eqs. 43-46: G_r [P_rr P_rm]
    p_new[n:, :n] = cross
    p_new[:n, n:] = cross.T
    block = gr2 @ p[:3, :3] @ gr2.T
    b4 = block.reshape(nl, 2, nl, 2)
    rows = np.arange(nl)
    b4[rows, :, rows, :] += gz @ r @ np.transpose(gz, (0, 2, 1))  # eq. 47-48
    p_new[n:, n:] = 0.5 * (block + block.T)
    return x_new, p_new


class MapManagement:
    """The :class:`~.ekf_slam.EkfSlam` steps that change which landmarks the state holds."""

    def _grow_extents(self, index: np.ndarray, ends_b: np.ndarray) -> None:
        """Extend matched line landmarks by their observed segments (updated pose)."""
        ln = np.flatnonzero(self._kind[index] == LINE)
        if ln.size == 0:
            return
        ends_w = ends_to_map(self._x[:3], ends_b[ln])
        lm = self._x[3:].reshape(-1, 2)
        for k, j in enumerate(index[ln]):
            self._ends[j] = merge_extent(lm[j], self._ends[j], ends_w[k])

    # ------------------------------------------------------------------ map management
    def _manages_map(self, scan: Optional[ScanGeometry]) -> bool:
        """Whether an update with this scan counts misses / chances (SLAM, a map, a scan)."""
        prm = self.params
        return (scan is not None and prm.mode == 'slam' and self.num_landmarks > 0
                and (prm.prune_misses > 0 or prm.establish_hits > 0))

    def _manage_by_visibility(self, scan: ScanGeometry, seen: np.ndarray,
                              near: np.ndarray) -> None:
        """Prune the landmarks the scan shows absent, retire unestablished ones.

        Args:
            scan: The scan's geometry.
            seen: (n,) landmarks detected in this scan (the first n of the state).
            near: (n,) landmarks an unassociated observation lay near.
        """
        prm = self.params
        drop = np.zeros(0, dtype=np.int64)
        if prm.prune_misses > 0:
            drop = self._count_misses(scan, seen | near)
        if prm.establish_hits > 0:
            retire = np.setdiff1d(self._count_chances(scan, seen, near), drop)
            self.stats['retired'] += int(retire.size)
            drop = np.union1d(drop, retire)
        if drop.size:
            self._remove_landmarks(drop)

    def _count_misses(self, scan: ScanGeometry, seen: np.ndarray) -> np.ndarray:
        """Count misses of landmarks the scan should have shown; return those to prune."""
        prm = self.params
        n = seen.size
        miss = np.zeros(n, dtype=bool)  # a scan without returns shows no landmark absent
        if scan.has_returns:
            index = np.arange(n)
            kind = self._kind[:n]
            zhat, hr, hf = observation_model(self._x, index, kind)
            var = np.diagonal(predicted_observation_covariance(self._p, index, hr, hf),
                              0, 1, 2)
            miss = landmarks_missed(self._x[:3], kind, self._x[3:3 + 2 * n].reshape(-1, 2),
                                    self._ends[:n], self._bis[:n], self._open[:n],
                                    np.sqrt(np.maximum(var, 0.0)), scan,
                                    math.sqrt(chi2_gate(1, prm.gate_probability)),
                                    prm.min_view_margin, prm.line_min_beams)
            miss &= ~seen
        self._misses[:n][miss] += 1
        self._misses[:n][seen] = 0
        drop = np.flatnonzero(self._misses[:n] >= prm.prune_misses)
        self.stats['pruned'] += int(drop.size)
        return drop

    def _count_chances(self, scan: ScanGeometry, seen: np.ndarray, near: np.ndarray
                       ) -> np.ndarray:
        """Count chances of provisional corners; return those to retire (module docstring).

        Args:
            scan: The scan's geometry.
            seen: (n,) landmarks detected in this scan (the first n of the state).
            near: (n,) landmarks an unassociated observation lay near (no chance, no hit).
        """
        prm = self.params
        n = seen.size
        # Detections of this scan are already in _rehits (a corner they establish is done).
        prov = np.flatnonzero((self._kind[:n] == CORNER) & (self._rehits[:n] < prm.establish_hits)
                              & (self._chances[:n] < prm.establish_chances))
        if prov.size == 0:
            return prov
        chance = seen[prov].copy()
        look = ~chance & ~near[prov]
        if np.any(look) and scan.has_returns:  # without returns no chance (corners_in_view)
            idx = prov[look]
            zhat, hr, hf = observation_model(self._x, idx)
            var = np.diagonal(predicted_observation_covariance(self._p, idx, hr, hf), 0, 1, 2)
            chance[look] = corners_in_view(
                self._x[:3], self._x[3:].reshape(-1, 2)[idx], self._bis[idx], self._open[idx],
                np.sqrt(np.maximum(var, 0.0)), self._max_seen[idx], scan,
                math.sqrt(chi2_gate(1, prm.gate_probability)), prm.min_view_margin)
        self._chances[prov[chance]] += 1
        out = (self._chances[prov] >= prm.establish_chances) & (
            self._rehits[prov] < prm.establish_hits)
        return prov[out]

    def _remove_landmarks(self, index: np.ndarray) -> None:
        """Marginalise landmarks out of the state (drop their rows and columns)."""
        keep = np.ones(self.num_landmarks, dtype=bool)
        keep[index] = False
        cols = np.concatenate([np.arange(3), _landmark_cols(np.flatnonzero(keep)).reshape(-1)])
        self._x = self._x[cols]
        self._p = self._p[np.ix_(cols, cols)]
        for name in ('_ids', '_kind', '_ends', '_bis', '_open', '_n_open', '_hits', '_misses',
                     '_rehits', '_chances', '_last_seen', '_max_seen', '_first'):
            setattr(self, name, getattr(self, name)[keep])

    def _make_room(self, need: int, protect: np.ndarray) -> int:
        """Evict up to ``need`` least recently seen landmarks; return the room made."""
        cand = np.setdiff1d(np.arange(self.num_landmarks), protect)
        if cand.size == 0 or need <= 0:
            return 0
        order = np.lexsort((self._hits[cand], self._last_seen[cand]))  # oldest, fewest hits
        drop = cand[order[:need]]
        self._remove_landmarks(drop)
        self.stats['evicted'] += int(drop.size)
        return int(drop.size)

    # ------------------------------------------------------------------ candidates
    def _handle_candidates(self, z: np.ndarray, r: np.ndarray, obs: np.ndarray,
                           bvec: np.ndarray, opening: np.ndarray, status: np.ndarray,
                           reason: np.ndarray, lm_id: np.ndarray, cand_id: np.ndarray,
                           kind: np.ndarray, ends_b: np.ndarray) -> None:
        """Match unexplained observations to candidates, start new ones, confirm (augment)."""
        prm = self.params
        if self.num_landmarks >= prm.max_landmarks and prm.map_full == 'reject':
            reason[obs] = 'cap'
            return
        line = kind == LINE
        g, gr, gz = feature_initialization(self._x[:3], z, kind)  # eq. 40, updated pose
        cov = (gr @ self._p[:3, :3] @ np.transpose(gr, (0, 2, 1))
               + gz @ r @ np.transpose(gz, (0, 2, 1)))
        ends_w = ends_to_map(self._x[:3], ends_b)
        assigned = np.full(z.shape[0], -1, dtype=np.int64)
        if self._candidates:
            cxy = np.array([c.xy for c in self._candidates])
            ccov = np.array([c.cov for c in self._candidates])
            ckind = np.array([c.kind for c in self._candidates])
            diff = g[:, None, :] - cxy[None]
            diff[..., 1] = np.where(line[:, None], _wrap(diff[..., 1]), diff[..., 1])
            d2 = mahalanobis_table(diff, cov[:, None] + ccov[None])
            d2 = np.where(kind[:, None] == ckind[None, :], d2, np.inf)
            cl = np.flatnonzero(ckind == LINE)
            if cl.size and np.any(line):
                ov = extents_overlap(cxy[cl], np.array([self._candidates[i].ends for i in cl]),
                                     ends_w[line])
                sub = d2[np.ix_(np.flatnonzero(line), cl)]
                d2[np.ix_(np.flatnonzero(line), cl)] = np.where(ov, sub, np.inf)
            allowed = self._descriptor_gate(
                bvec, opening, np.array([c.bis for c in self._candidates]),
                np.array([c.opening for c in self._candidates]))
            if allowed is not None:
                d2 = np.where(allowed, d2, np.inf)
            assigned = icnn(d2, chi2_gate(2, prm.candidate_probability))
        confirm: List[int] = []
        for k in range(z.shape[0]):
            i = int(obs[k])
            if assigned[k] >= 0:
                c = self._candidates[int(assigned[k])]
                info_old, info_new = np.linalg.inv(c.cov), np.linalg.inv(cov[k])
                c.cov = np.linalg.inv(info_old + info_new)
                c.cov = 0.5 * (c.cov + c.cov.T)
                dg = g[k] - c.xy
                if line[k]:
                    dg[1] = _wrap(dg[1])
                c.xy = c.xy + c.cov @ info_new @ dg  # information-form fusion
                if line[k]:
                    c.xy[1] = _wrap(c.xy[1])
                    c.ends = merge_extent(c.xy, c.ends, ends_w[k])
                c.hits += 1
                c.max_seen = max(c.max_seen, float(z[k, 0]))
                c.bis = c.bis + bvec[k]
                if np.isfinite(opening[k]):
                    prev = c.opening if c.n_open else 0.0
                    c.n_open += 1
                    c.opening = prev + (opening[k] - prev) / c.n_open
                cand_id[i] = c.cid
                status[i] = 'tentative'
                if c.hits >= prm.confirm_hits:
                    confirm.append(k)
            else:
                has = bool(np.isfinite(opening[k]))
                c = _Candidate(cid=self._next_cid, xy=g[k].copy(), cov=cov[k].copy(),
                               first_scan=self._scan, hits=1, bis=bvec[k].copy(),
                               opening=float(opening[k]) if has else math.nan,
                               n_open=int(has), kind=int(kind[k]),
                               ends=project_extent(g[k], ends_w[k]) if line[k] else None,
                               max_seen=float(z[k, 0]))
                self._next_cid += 1
                self._candidates.append(c)
                self.stats['new_candidates'] += 1
                cand_id[i] = c.cid
                status[i] = 'new'
                if prm.confirm_hits <= 1:
                    confirm.append(k)
        if not confirm:
            return
        room = prm.max_landmarks - self.num_landmarks
        if room < len(confirm) and prm.map_full == 'evict':
            matched = np.flatnonzero(self._last_seen == self._scan)
            room += self._make_room(len(confirm) - room, matched)
        room = max(room, 0)
        take = np.array(confirm[:room], dtype=np.int64)
        for k in confirm[room:]:
            status[obs[k]] = 'rejected'
            reason[obs[k]] = 'cap'
        if take.size == 0:
            return
        oc = prm.jacobians in _FIRST_ESTIMATE_RULES
        self._x, self._p = augment_map(self._x, self._p, z[take], r[take], kind[take],
                                       self._prior_xy if oc else None)  # eqs. 38-48
        new_ids = self._next_id + np.arange(take.size, dtype=np.int64)
        self._next_id += take.size
        self._ids = np.concatenate([self._ids, new_ids])
        by_id = {c.cid: c for c in self._candidates}
        new_c = [by_id[int(cand_id[obs[k]])] for k in take]
        self._kind = np.concatenate([self._kind, kind[take].astype(np.int8)])
        lm_new = self._x[3:].reshape(-1, 2)[-take.size:]
        ends_new = np.full((take.size, 2, 2), np.nan)
        for q, (k, c) in enumerate(zip(take, new_c)):
            if line[k]:
                ends_new[q] = merge_extent(lm_new[q], c.ends, ends_w[k])
        self._ends = np.concatenate([self._ends, ends_new])
        self._bis = np.vstack([self._bis, np.array([c.bis for c in new_c])])
        self._open = np.concatenate([self._open, [c.opening for c in new_c]])
        self._n_open = np.concatenate([self._n_open, [c.n_open for c in new_c]])
        self._hits = np.concatenate([self._hits, [c.hits for c in new_c]])
        self._misses = np.concatenate([self._misses, np.zeros(take.size, dtype=np.int64)])
        self._rehits = np.concatenate([self._rehits, np.zeros(take.size, dtype=np.int64)])
        self._chances = np.concatenate([self._chances, np.zeros(take.size, dtype=np.int64)])
        self._last_seen = np.concatenate([self._last_seen,
                                          np.full(take.size, self._scan, dtype=np.int64)])
        self._max_seen = np.concatenate([self._max_seen, [c.max_seen for c in new_c]])
        self._first = np.vstack([self._first, self._x[3:].reshape(-1, 2)[-take.size:]])
        done = {int(cand_id[obs[k]]) for k in take}
        self._candidates = [c for c in self._candidates if c.cid not in done]
        status[obs[take]] = 'confirmed'
        lm_id[obs[take]] = new_ids
        cand_id[obs[take]] = -1
        self.stats['confirmed'] += int(take.size)

    def _expire_candidates(self) -> None:
        """Drop candidates whose confirmation window has passed."""
        keep = [c for c in self._candidates
                if self._scan - c.first_scan + 1 < self.params.confirm_window]
        self.stats['dropped_candidates'] += len(self._candidates) - len(keep)
        self._candidates = keep
