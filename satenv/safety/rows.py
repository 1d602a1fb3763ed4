"""The constraint rows (C1), (C2) of every position slot and the velocity boxes (:mod:`satenv.safety`)."""

from __future__ import annotations

import numpy as np

from satenv.dynamics import attitude_step
from satenv.safety.config import _BIG, _FLOOR, SafetyConfig
from satenv.safety.margins import estimated_agents, tighten_geometry, velocity_error
from satenv.safety.model import SafetyModel, courtesy


# ---------------------------------------------------------------------------------------------
# constraint rows
# ---------------------------------------------------------------------------------------------
def _barrier(m: SafetyModel, cfg: SafetyConfig, gap0, rate0, gap_bar, dirn, vel_bar, brake, span):
    """Rows (C1), (C2) of the module docstring in acceleration space: ``w^T du >= -g``.

    ``gap0, rate0``: the gap and its rate now; ``gap_bar, dirn, vel_bar``: the coasting gap, the
    direction ``n`` and relative velocity at the next decision; ``brake`` the pair's ``a``;
    ``span`` the bound ``delta`` on ``|n^T B_p du|``. Returns ``(w1, g1, w2, g2, h)``, ``h`` the
    barrier now.
    """
    bp, bv = m.B[:3], m.B[3:]
    w1 = dirn @ bp
    s_lo = np.maximum(gap_bar - span, 0.0)
    s_hi = np.maximum(gap_bar + span, s_lo + 1e-12)
    slope = (np.sqrt(s_hi) - np.sqrt(s_lo)) / (s_hi - s_lo)
    c = np.sqrt(2.0 * brake)
    w2 = dirn @ bv + (c * slope)[..., None] * w1
    h0 = rate0 + c * np.sqrt(np.maximum(gap0, 0.0))
    g2 = (np.sum(dirn * vel_bar, axis=-1) + c * (np.sqrt(s_lo) + slope * (gap_bar - s_lo))
          - (1.0 - cfg.gamma) * h0)
    return w1, gap_bar, w2, g2, h0


def _sphere(cfg, r, r_bar, radius):
    """Geometry of ``||r_p|| >= radius`` for relative states ``r`` (now) and ``r_bar`` (coasting,
    next decision), ``(..., 6)``: ``(gap0, rate0, gap_bar, dirn, vel_bar)``, ``dirn`` the unit
    coasting direction (the margin: :class:`SafetyConfig`, never beyond the current gap)."""
    d0 = np.sqrt(np.einsum("...i,...i->...", r[..., :3], r[..., :3]))
    d_m = radius + np.minimum(cfg.margin * radius, np.maximum(d0 - radius, 0.0))
    d_bar = np.sqrt(np.einsum("...i,...i->...", r_bar[..., :3], r_bar[..., :3]))
    dirn = r_bar[..., :3] / np.maximum(d_bar, 1e-12)[..., None]
    rate0 = np.einsum("...i,...i->...", r[..., :3], r[..., 3:]) / np.maximum(d0, 1e-12)
    return d0 - d_m, rate0, d_bar - d_m, dirn, r_bar[..., 3:]


def _halfspaces(cfg, r, r_bar, normals, bounds):
    """Geometry of ``normals_k^T r_p <= bounds_k`` (``(K, 3)``, ``(K,)``) for ``r``, ``r_bar``
    ``(..., 6)``: arrays ``(..., K)``; the gap grows along ``-normal``."""
    gap0 = bounds - r[..., :3] @ normals.T
    b_m = bounds - np.minimum(cfg.los_margin, np.maximum(gap0, 0.0))
    dirn = np.broadcast_to(-normals, (*r.shape[:-1], *normals.shape))
    vel = np.repeat(r_bar[..., None, 3:], len(bounds), axis=-2)
    return b_m - r[..., :3] @ normals.T, -(r[..., 3:] @ normals.T), b_m - r_bar[..., :3] @ normals.T, dirn, vel


def _drift(m: SafetyModel, state: np.ndarray) -> np.ndarray:
    """Bound on the CW drift acceleration of a relative state: ``3 n^2 ||r_p|| + 2 n ||r_v||``."""
    sq = state[..., :6] * state[..., :6]
    return 3.0 * m.n**2 * np.sqrt(sq[..., :3].sum(-1)) + 2.0 * m.n * np.sqrt(sq[..., 3:].sum(-1))


def constraint_rows(m: SafetyModel, cfg: SafetyConfig, x: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every agent's rows ``w^T (S_i u_i) >= l`` in acceleration space: ``w (B, M, K, 3)``,
    ``l (B, M, K)`` (``l = -1e30``: an unused slot); ``K = len(m.kinds)`` minus the
    angular-velocity rows (:func:`_omega_rows`, in action space).

    Every position constraint is one slot ``(gap0, rate0, gap_bar, dirn, vel_bar)`` with a budget
    ``(own, other)`` (the fractions of each agent's braking authority the pair may use; ``other
    = 0``: a body or the passive leader) and a drift bound; one :func:`_barrier` call serves all.
    """
    x6 = x[..., :6]
    xb = x6 @ m.A.T                                       # coasting prediction of every agent
    bsz, na = x6.shape[:2]
    geos: list[tuple] = []                                # (gap0, rate0, gap_bar, dirn, vel_bar), (B, M, k)
    drifts: list[np.ndarray] = []
    dists: list[np.ndarray] = []                          # predicted distance (inf: a half-space)
    if m.pair_distance > 0:
        r = x6[:, :, None] - x6[:, None]                  # (B, M, M, 6): agent i minus agent j
        geos.append(_sphere(cfg, r, xb[:, :, None] - xb[:, None], m.pair_distance))
        drifts.append(_drift(m, r))
        dists.append(_norm(xb[:, :, None, :3] - xb[:, None, :, :3]))
    if m.bodies:   # (B, nb, 6) body states now and at the next decision (their own motion)
        centre = m.body_state[None, :, :3] + t[:, None, None] * m.body_state[None, :, 3:]
        now = np.concatenate([centre, np.broadcast_to(m.body_state[None, :, 3:], centre.shape)], -1)
        nxt = now + m.dt * np.concatenate([m.body_state[:, 3:], np.zeros((len(m.bodies), 3))], -1)
        geos.append(_sphere(cfg, x6[:, :, None] - now[:, None], xb[:, :, None] - nxt[:, None], m.body_radius))
        drifts.append(np.repeat(_drift(m, x6)[..., None], len(m.bodies), axis=-1))
        dists.append(_norm(xb[:, :, None, :3] - nxt[:, None, :, :3]))
    n_chain = m.n_chain
    if n_chain:
        zero = np.zeros_like(x6[:, :1])
        r = x6 - np.concatenate([zero, x6[:, :-1]], axis=1)
        rb = xb - np.concatenate([zero, xb[:, :-1]], axis=1)
        if m.chain_sphere is not None:
            off = np.r_[m.chain_sphere[0], np.zeros(3)]
            geos.append(tuple(v[:, :, None] for v in _sphere(cfg, r - off, rb - off, m.chain_sphere[1])))
            dists.append(_norm(rb[..., None, :3] - off[:3]))
        if m.chain_halfspaces is not None:
            geos.append(_halfspaces(cfg, r, rb, *m.chain_halfspaces))
            dists.append(np.full((bsz, na, len(m.chain_halfspaces[1])), np.inf))
        drifts.append(np.repeat(_drift(m, r)[..., None], n_chain, axis=-1))
    ws: list[np.ndarray] = []
    ls: list[np.ndarray] = []
    if geos:
        geo = [np.concatenate([g[f] for g in geos], axis=2) if len(geos) > 1 else geos[0][f] for f in range(5)]
        geo = tighten_geometry(m, geo, np.concatenate(dists, axis=2), estimated_agents(m))
        drift = np.concatenate(drifts, axis=2) if len(drifts) > 1 else drifts[0]
        w1, l1, w2, l2, h0 = _shared(m, cfg, m.budget[0], m.budget[1], drift, *geo)
        if m.pair_distance > 0:                            # an agent and itself: no row
            eye = np.eye(na, dtype=bool)
            l1[..., :na] = np.where(eye, -_BIG, l1[..., :na])
            l2[..., :na] = np.where(eye, -_BIG, l2[..., :na])
        ws += [w1, w2]
        ls += [l1, l2]
        if n_chain:   # courtesy: the target f - 1 of a chaser near its bound, along n <= c_{f-1} a
            near = h0[:, :, -n_chain:] < 3.0 * m.accel_max * m.dt
            bound = -(courtesy(na) * m.brake)[None, :, None]      # shifted: agent f - 1 gets c_{f-1}
            ws.append(_up(-geo[3][:, :, -n_chain:], 0.0))
            ls.append(np.where(_up(near, False), np.broadcast_to(bound, near.shape), -_BIG))
    if m.v_max > 0:
        _velocity_rows(m, cfg, x6, xb, ws, ls)
    if not ws:                                            # e.g. formation_v0 at collision_distance = 0
        return np.zeros((bsz, na, 0, 3)), np.zeros((bsz, na, 0))
    w = np.concatenate([v.reshape(bsz, na, -1, 3) for v in ws], axis=2)
    lo = np.concatenate([v.reshape(bsz, na, -1) for v in ls], axis=2)
    return w, lo


def _shared(m, cfg, own, other, drift, gap0, rate0, gap_bar, dirn, vel_bar):
    """:func:`_barrier` with the pair's authority, and this agent's share of the rows.

    ``a = (own + other) (1 - theta) a_i`` minus the drift bound, the disturbance of each moving
    agent and the declared disturbance bound of each estimated one (:mod:`satenv.safety.margins`;
    floored at ``_FLOOR`` of the nominal: there the barrier is no longer a guarantee);
    ``delta = ||B_p|| max ||S u||`` per moving agent; this agent's share ``own / (own + other)``.
    """
    units, movers = own + other, 1.0 + (other > 0)
    authority = units * m.brake * (1.0 - m.bounds.thrust)
    unmodelled = estimated_agents(m) * m.bounds.disturbance
    brake = np.maximum(authority - movers * m.disturbance - unmodelled - drift, _FLOOR * authority)
    w1, g1, w2, g2, h0 = _barrier(m, cfg, gap0, rate0, gap_bar, dirn, vel_bar, brake, movers * m.reach * m.accel_max)
    share = own / units
    return w1, -share * g1, w2, -share * g2, h0


def _norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("...i,...i->...", v, v))


def _up(v: np.ndarray, fill: float) -> np.ndarray:
    """``v`` of agent ``f`` moved to agent ``f - 1`` (the last agent gets ``fill``)."""
    out = np.full_like(v, fill)
    out[:, :-1] = v[:, 1:]
    return out


def _velocity_rows(m, cfg, x6, xb, ws, ls) -> None:
    """Velocity boxes (relative degree one): ``|e_k^+| <= V`` per axis, two rows each, for
    ``e = (Lbar x)_f`` (platoon: bound (40), ``V = (g_f + d_f) v_max``; the neighbours' inputs
    taken at their worst, ``beta = d_f ||(B_v S)_k||_1 u_box``) or ``e = v_i`` (servicing)."""
    bv = m.B[3:]
    if m.lbar is not None:
        gd = np.diag(m.lbar)
        e_bar = np.einsum("ij,bjk->bik", m.lbar, xb[..., 3:])
        heard = -(m.lbar - np.diag(gd)).sum(axis=1)
        beta = heard[:, None] * (np.abs(bv @ m.S).sum(axis=1) * m.u_box)[None, :]
        v_lim = gd[:, None] * m.v_max - np.abs(m.lbar).sum(axis=1)[:, None] * velocity_error(m)
        gain = gd[:, None, None] * bv[None]
    else:
        e_bar = xb[..., 3:]
        beta = 0.0
        v_lim = m.v_max - velocity_error(m)
        gain = bv[None]
    lim = v_lim * (1.0 - cfg.velocity_margin)     # one decision can always come back inside
    g = np.broadcast_to(gain, (*x6.shape[:2], 3, 3))
    ws.extend([g, -g])
    ls.extend([-lim - e_bar + beta, -lim + e_bar + beta])


def _omega_rows(m: SafetyModel, cfg: SafetyConfig, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Servicing ``|omega_k^+| <= omega_max`` (relative degree one) in action space: the coasting
    ``omega^+`` of the env's attitude step, plus ``dt J_f^-1 F_r diag(u_max) u`` (first order)."""
    j_f, j_l, omega_l, w_max, gain, sub = m.attitude
    w_now = x[..., 10:13]
    _, w_bar = attitude_step(x[..., 6:10], w_now, np.zeros_like(w_now), m.dt, j_f, j_l, omega_l, sub)  # coasting
    lim = w_max * (1.0 - cfg.velocity_margin)
    g = np.broadcast_to(gain, (*x.shape[:2], *gain.shape))
    return np.concatenate([g, -g], axis=2), np.concatenate([-lim - w_bar, -lim + w_bar], axis=2)
