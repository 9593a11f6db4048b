"""Laplace approximations of a vectorised log density, and the sampling coordinates that undo a hierarchical funnel.

- `laplace_covariance`: the inverse of the finite-difference Hessian of −ln p at a point (the Laplace approximation's
  covariance; Gelman et al., Bayesian Data Analysis, 3rd ed., §4.1).
- `conditional_mode`: Newton's method on ln p from a nearby point, each step C ∇ln p with C that covariance, halved
  until ln p does not fall.
- Edges: a fit's discrepancies are bounded at 0, and in a world the model describes exactly their modes are there
  (1e-18 after the start's search). The differences' stencil is then centred 2 STEP inside in that coordinate,
  which gives the edge's curvature to O(STEP), and Newton's step holds a coordinate on its edge whose gradient
  points out. Before, the stencil shrank with the distance to the bound, the Hessian came out as rounding noise,
  no coordinates were built and the fit ran in the funnel: 11,750 steps on the linear tank world of
  tests/slow/test_trend_check_worlds.py (seed 4), 3,000 now.
- `ScaleConditioned`: sampling coordinates for a posterior with a scale τ (the between-configuration discrepancy)
  that sets how tightly the data hold the other parameters. In a hierarchical model the data fix the
  configurations' levels only to within τ, so the parameters that carry the levels (gains, lens factors) have a
  conditional spread that grows with τ: a funnel (Neal, Ann. Statist. 31, 705–767, 2003, §8), through which an
  ensemble sampler neither enters the wide region nor reports that it has not — its autocorrelation time and R̂
  look fine while the tail of τ is missed (on the seed-0 demo, P(τ > 0.13 %) came out 6 % against 37 % by
  importance sampling). The cure is to sample what is not funnelled (Papaspiliopoulos, Roberts & Sköld,
  Statist. Sci. 22, 59–73, 2007, on centred and non-centred parametrisations); here, generically, from Laplace
  approximations: on a grid of v = ln τ the others' conditional mode m(v) and the Cholesky factor L(v) of their
  conditional covariance, interpolated linearly in v (clamped beyond the grid), and the sampler moves in
  w = (v, z) with u_others = m(v) + L(v) z. Where the conditional is Gaussian z is a standard normal whatever τ;
  where it is not, the sampler still sees a far rounder density. The map is triangular, so the log-Jacobian is
  v + Σ ln diag L(v), and the density is exact: the approximations only choose coordinates.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

LogDensity = Callable[[np.ndarray], np.ndarray]  # rows of points (n, d) → ln p (n,)

STEP = 1e-4  # finite-difference step in the sampling coordinates (logs: relative); a coordinate within the stencil's
# reach of its support's edge is differenced from inside (`_inside`)
NEWTON_STEPS = 20
GRID_SPACING = 0.5  # in ln τ: the conditional moves smoothly over a factor 1.65
SCALE_RANGE = (0.001, 0.997)  # the prior quantiles of τ the grid spans; beyond, the end's coordinates are kept
MARGINAL_CELLS = 300  # cells of the independence proposal's piecewise-constant density of v
# ...spanning the grid and beyond it, down to τ e⁻⁸ smaller (below the data's resolution the likelihood is flat and
# p(v) ∝ e^v: a walker beyond the proposal's support could never leave by this move) and e¹ larger
MARGINAL_BEYOND = (8.0, 1.0)
PROPOSAL_SPREAD = 1.2  # the independence proposal's z: N(0, PROPOSAL_SPREAD² I), wider than the Laplace's N(0, I)


def laplace_covariance(log_density: LogDensity, theta: np.ndarray) -> np.ndarray | None:
    """Inverse of the finite-difference Hessian of −log p at θ (all evaluations in one vectorised call), centred
    inside where θ is on its support's edge (`_inside`); None when it is not finite or not positive definite.

    >>> half_normal = lambda x: np.where(x[:, 0] > 0, -0.5 * (x[:, 0] / 0.5) ** 2, -np.inf)  # its mode on the edge
    >>> round(float(laplace_covariance(half_normal, np.array([1e-18]))[0, 0]), 9)
    0.25
    """
    return _curvature(log_density, theta)[0]


def _curvature(log_density: LogDensity, theta: np.ndarray) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
    """(`laplace_covariance`, then `_inside`'s centre and edge, which Newton's step at θ differences from too)."""
    n = theta.size
    c, edge = _inside(log_density, theta)
    eye = STEP * np.eye(n)
    pts = []
    for i in range(n):
        for j in range(n):
            pts += [c + eye[i] + eye[j], c + eye[i] - eye[j], c - eye[i] + eye[j], c - eye[i] - eye[j]]
    values = log_density(np.array(pts))
    hess = np.empty((n, n))
    k = 0
    with np.errstate(invalid="ignore", over="ignore"):
        for i in range(n):
            for j in range(n):
                pp, pm, mp, mm = values[k : k + 4]
                hess[i, j] = -(pp - pm - mp + mm) / (4 * STEP**2)
                k += 4
    if not np.all(np.isfinite(hess)):
        return None, c, edge
    try:
        cov = np.linalg.inv(0.5 * (hess + hess.T))
        np.linalg.cholesky(cov)
        return cov, c, edge
    except np.linalg.LinAlgError:
        return None, c, edge


def _inside(log_density: LogDensity, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(centre, edge): where a finite-difference stencil at x is centred. A coordinate on its support's edge (the
    density is −inf the stencil's reach, 2 STEP, below it and finite as far above, or the reverse) is moved that
    reach inside: edge +1 for a lower edge, −1 for an upper one, 0 elsewhere. A mode on a bound (a discrepancy the
    data cannot tell from zero: 1e-18 after the start's search) then has the curvature 2 STEP inside, its own to
    O(STEP)."""
    reach = 2 * STEP * np.eye(x.size)
    values = log_density(np.concatenate([x - reach, x + reach]))
    below, above = ~np.isfinite(values[: x.size]), ~np.isfinite(values[x.size :])
    edge = (below & ~above).astype(float) - (above & ~below)
    return x + 2 * STEP * edge, edge


def _newton_step(log_density: LogDensity, centre: np.ndarray, edge: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """C ∇ln p, the gradient by central differences at `_inside`'s centre. A coordinate on its edge whose gradient
    points out of the support stays there; the others take the Newton step of their conditional given it."""
    n = centre.size
    steps = STEP * np.eye(n)
    values = log_density(np.concatenate([centre + steps, centre - steps]))
    gradient = (values[:n] - values[n:]) / (2 * STEP)
    held = edge * gradient < 0
    if not held.any():
        return cov @ gradient
    free = ~held
    step = np.zeros(n)
    step[free] = np.linalg.solve(np.linalg.inv(cov)[np.ix_(free, free)], gradient[free])
    return step


def conditional_mode(log_density: LogDensity, x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(mode, Laplace covariance there) by Newton's method from x (module docstring); the covariance is None where
    the Hessian is not positive definite, and the search stops at the last point where it was. A mode on its
    support's edge is found there (`_newton_step`).

    >>> mode, cov = conditional_mode(lambda x: -0.5 * ((x - [1.0, -2.0]) ** 2 / [1.0, 4.0]).sum(axis=1), np.zeros(2))
    >>> mode.round(6).tolist(), np.diag(cov).round(4).tolist()
    ([1.0, -2.0], [1.0, 4.0])
    >>> edge = lambda x: np.where(x[:, 0] > 0, -((x + [1, 0]) ** 2).sum(axis=1) / 2 + x.prod(axis=1) / 2, -np.inf)
    >>> mode, cov = conditional_mode(edge, np.array([1e-18, 1.0]))  # x₀ held at its edge, x₁ | x₀ ≈ 0 ~ N(0, 1)
    >>> float(mode[0]) == 1e-18, round(float(mode[1]), 3)
    (True, 0.0)
    """
    cov, centre, edge = _curvature(log_density, x)
    for _ in range(NEWTON_STEPS):
        if cov is None:
            break
        step = _newton_step(log_density, centre, edge, cov)
        here = log_density(x[None, :])[0]
        for _ in range(30):
            if log_density((x + step)[None, :])[0] >= here:
                break
            step = 0.5 * step
        else:
            break
        x = x + step
        cov, centre, edge = _curvature(log_density, x)
        if np.max(np.abs(step) / np.sqrt(np.diag(cov) if cov is not None else 1.0)) < 1e-6:
            break
    return x, cov


class ScaleConditioned:
    """Sampling coordinates w = (v = ln τ at `index`, z elsewhere) over a log density in coordinates u (module
    docstring), built around the mode `u_mode` for τ within `scale_range` (its prior's quantiles).

    Use `around`, which returns None where the approximation cannot be built (a Hessian not positive definite at
    the mode) and the sampler keeps the coordinates u."""

    CHUNK = 20_000  # rows per mapping of a whole chain: (CHUNK, d − 1, d − 1) interpolated factors

    def __init__(self, log_u: LogDensity, grid: np.ndarray, index: int, modes: np.ndarray, factors: np.ndarray):
        self.log_u, self.grid, self.index = log_u, grid, index
        self.others = np.delete(np.arange(modes.shape[1] + 1), index)
        self.modes, self.factors = modes, factors  # (grid, d − 1), (grid, d − 1, d − 1): m(v), L(v)

    @classmethod
    def around(
        cls, log_u: LogDensity, u_mode: np.ndarray, index: int, scale_range: tuple[float, float]
    ) -> ScaleConditioned | None:
        lo, hi = np.log(scale_range[0]), np.log(scale_range[1])
        v_mode = float(np.clip(np.log(max(u_mode[index], scale_range[0])), lo, hi))
        below = np.arange(v_mode, lo - GRID_SPACING, -GRID_SPACING)[::-1]
        grid = np.concatenate([below, np.arange(v_mode + GRID_SPACING, hi + GRID_SPACING, GRID_SPACING)])
        others = np.delete(np.arange(u_mode.size), index)
        start = below.size - 1
        modes = np.empty((grid.size, others.size))
        factors = np.empty((grid.size, others.size, others.size))
        # outwards from the mode's τ in both directions, each conditional mode started from its neighbour's; where a
        # conditional is not approximable the neighbour's coordinates are kept
        for sequence in (range(start, grid.size), range(start - 1, -1, -1)):
            x, factor = u_mode[others], None
            for j in sequence:
                x_new, cov = conditional_mode(cls._conditional(log_u, others, index, np.exp(grid[j])), x)
                if cov is not None:
                    x, factor = x_new, np.linalg.cholesky(cov)
                elif factor is None:
                    return None
                modes[j], factors[j] = x, factor
        return cls(log_u, grid, index, modes, factors)

    @staticmethod
    def _conditional(log_u: LogDensity, others: np.ndarray, index: int, scale: float) -> LogDensity:
        """ln p of the `others` coordinates with τ (at `index`) held at `scale`."""

        def density(x: np.ndarray) -> np.ndarray:
            u = np.empty((x.shape[0], others.size + 1))
            u[:, others] = x
            u[:, index] = scale
            return log_u(u)

        return density

    def _at(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """m(v), L(v) for rows v, linear between grid points, the ends' beyond them."""
        v = np.clip(v, self.grid[0], self.grid[-1])
        if self.grid.size == 1:
            return np.repeat(self.modes, v.size, axis=0), np.repeat(self.factors, v.size, axis=0)
        j = np.clip(np.searchsorted(self.grid, v) - 1, 0, self.grid.size - 2)
        a = (v - self.grid[j]) / (self.grid[j + 1] - self.grid[j])
        m = self.modes[j] + a[:, None] * (self.modes[j + 1] - self.modes[j])
        factor = self.factors[j] + a[:, None, None] * (self.factors[j + 1] - self.factors[j])
        return m, factor

    def to_u(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u, ln |∂u/∂w|) for rows w of shape (n, d)."""
        v = w[:, self.index]
        m, factor = self._at(v)
        u = np.empty_like(w)
        u[:, self.index] = np.exp(v)
        u[:, self.others] = m + np.einsum("nij,nj->ni", factor, w[:, self.others])
        with np.errstate(divide="ignore"):
            log_jacobian = v + np.log(np.abs(np.diagonal(factor, axis1=1, axis2=2))).sum(axis=1)
        return u, log_jacobian

    def to_w(self, u: np.ndarray) -> np.ndarray:
        """w for rows u of shape (n, d) with τ > 0."""
        v = np.log(u[:, self.index])
        m, factor = self._at(v)
        w = np.empty_like(u)
        w[:, self.index] = v
        w[:, self.others] = np.linalg.solve(factor, (u[:, self.others] - m)[:, :, None])[:, :, 0]
        return w

    def u_of(self, w: np.ndarray) -> np.ndarray:
        """u for w of any leading shape (whole chains, CHUNK rows at a time)."""
        flat = w.reshape(-1, w.shape[-1])
        parts = [self.to_u(flat[i : i + self.CHUNK])[0] for i in range(0, flat.shape[0], self.CHUNK)]
        return np.concatenate(parts).reshape(w.shape)

    def log_w(self, w: np.ndarray) -> np.ndarray:
        """ln p(w) = ln p(u(w)) + ln |∂u/∂w|."""
        u, log_jacobian = self.to_u(np.atleast_2d(w))
        with np.errstate(invalid="ignore"):
            out = self.log_u(u) + log_jacobian
        return np.where(np.isnan(out), -np.inf, out)


class MarginalProposal:
    """An independence Metropolis–Hastings proposal in a `ScaleConditioned`'s coordinates w (Tierney, Ann. Statist.
    22, 1701–1762, 1994, §2.3.3), callable as `emcee.moves.MHMove`'s proposal function: v from the Laplace
    approximation of its marginal and z ~ N(0, s² I) (s = `PROPOSAL_SPREAD`), whatever the walker's position.
    Where every conditional is Gaussian, p(v, z) = p(v, 0) exp(−|z|²/2) exactly, so the marginal of v is ∝ p(v, 0):
    it is tabulated on `MARGINAL_CELLS` cells (`MARGINAL_BEYOND`) and drawn as a piecewise-constant density. The
    move's acceptance ratio carries ln q(w) − ln q(w′), so it leaves the posterior invariant however good the
    approximation is; a good one moves a walker across τ's whole range in one step, where ensemble moves diffuse.

    >>> from uwlab.experiments.calibration.laplace import MarginalProposal, ScaleConditioned
    >>> def funnel(u):  # Neal's funnel in u = (s, x): ln s ~ N(0, 1.5²), x | s ~ N(0, s²)
    ...     s, x = u[:, 0], u[:, 1]
    ...     return -0.5 * (np.log(s) / 1.5) ** 2 - 2 * np.log(s) - 0.5 * (x / s) ** 2
    >>> proposal = MarginalProposal(ScaleConditioned.around(funnel, np.array([1.0, 0.0]), 0, (0.01, 100.0)))
    >>> v = proposal.draw(100_000, np.random.RandomState(0))[:, 0]
    >>> abs(float(v.mean())) < 0.02, round(float(v.std()), 1)
    (True, 1.5)
    """

    def __init__(self, coordinates: ScaleConditioned):
        self.index, self.others = coordinates.index, coordinates.others
        grid = coordinates.grid
        self.edges = np.linspace(grid[0] - MARGINAL_BEYOND[0], grid[-1] + MARGINAL_BEYOND[1], MARGINAL_CELLS + 1)
        centres = np.zeros((MARGINAL_CELLS, self.others.size + 1))
        centres[:, self.index] = 0.5 * (self.edges[1:] + self.edges[:-1])
        log_mass = coordinates.log_w(centres)
        mass = np.exp(log_mass - np.max(log_mass))
        self.mass = mass / mass.sum()
        with np.errstate(divide="ignore"):
            self.log_density = np.log(self.mass / np.diff(self.edges))  # −inf in cells of no mass, never proposed

    def log_q(self, w: np.ndarray) -> np.ndarray:
        """ln q(w) for rows w (−inf outside the tabulated range of v)."""
        v = w[:, self.index]
        cell = np.clip(np.searchsorted(self.edges, v) - 1, 0, MARGINAL_CELLS - 1)
        inside = (v >= self.edges[0]) & (v <= self.edges[-1])
        z = w[:, self.others] / PROPOSAL_SPREAD
        gauss = -0.5 * (z**2).sum(axis=1) - self.others.size * np.log(PROPOSAL_SPREAD * np.sqrt(2 * np.pi))
        return np.where(inside, self.log_density[cell], -np.inf) + gauss

    def draw(self, n: int, random: np.random.RandomState) -> np.ndarray:
        """n independent draws from q, rows of w."""
        cell = random.choice(MARGINAL_CELLS, size=n, p=self.mass)
        w = np.empty((n, self.others.size + 1))
        w[:, self.index] = self.edges[cell] + random.uniform(size=n) * (self.edges[cell + 1] - self.edges[cell])
        w[:, self.others] = PROPOSAL_SPREAD * random.standard_normal((n, self.others.size))
        return w

    def __call__(self, coords: np.ndarray, random: np.random.RandomState) -> tuple[np.ndarray, np.ndarray]:
        """(proposals, ln q(w) − ln q(w′)) for the walkers at `coords` (`emcee.moves.MHMove`'s contract)."""
        new = self.draw(coords.shape[0], random)
        return new, self.log_q(coords) - self.log_q(new)
