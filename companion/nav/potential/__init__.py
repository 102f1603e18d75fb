"""Position-potential filter with self-learned dissipation α and coupling G.

Grzegorzewski (2005): every accepted GNSS fix ``i`` (time ``t_i``, position
``r_0i``, per-axis variances ``σ²_ki``) is the source of an attracting
potential that dissipates in time. With the time origin at the newest source
(``t_n = 0``), each NED axis ``k`` of the particle obeys

    k̈(t) = −G A_k e^{−α t} (k − B_k/A_k),
    A_k = 2 Σ_i e^{α(t_i − t_n)} p_ki,   B_k = 2 Σ_i e^{α(t_i − t_n)} p_ki k_0i,

solved in closed form by Bessel functions of order 0 (the paper's
(4.55)-(4.62), corrected; :mod:`~companion.nav.potential.bessel`).

**Weights relative to the newest fix** (a deviation from the paper): the
paper's weights are ``p = 1/σ²``, so ``G·A`` scales with the receiver's
accuracy class: the paper flew DGPS (σ ≈ 1 m, p ≈ 1 m⁻²) and found
G ≈ 0.2-0.5; RTK's σ = 1.5 cm makes p ≈ 4400 m⁻² and the same G a field
thousands of times stiffer, which holds the particle on the centroid of the
recent fixes, behind the aircraft. Here ``p_ki = σ²_nk / σ²_ki``, the newest
fix's variance over the source's, per axis: ``A_k`` is dimensionless
(``2 Σ e^{α(t_i − t_n)}`` for fixes of equal accuracy), ``G`` and ``G·A_k``
are in 1/s², and the paper's α and G keep their meaning at σ ≈ 1 m for DGPS
and RTK alike; the relative weighting of sources of different accuracy is
the paper's.

The package, in the order a fix goes through it:

* :mod:`~companion.nav.potential.config`: :class:`PotentialConfig`;
* :mod:`~companion.nav.potential.filter`: :class:`PotentialFilter`, which
  tests each fix against its prediction (the paper's χ² test), carries the
  particle to it (with a position update and a velocity reset, two
  deviations from the paper), predicts through a gap with the field frozen,
  and restarts after a run of inconsistent fixes;
* :mod:`~companion.nav.potential.window`: the fixes acting as sources and the
  particle's velocity at each (the receiver's weighed against a least-squares
  one);
* :mod:`~companion.nav.potential.anchor`: the particle after a fix and its
  fast closed-form propagation;
* :mod:`~companion.nav.potential.bessel`: the closed form;
* :mod:`~companion.nav.potential.calibration`: the predictions' covariance,
  calibrated on the filter's own residuals;
* :mod:`~companion.nav.potential.fit`: the self-learning of α and G (the
  paper's objective plus gap-prediction terms) by differential evolution;
* :mod:`~companion.nav.potential.schedule`: when α and G are refitted;
* :mod:`~companion.nav.potential.combine`: the INS and potential predictions
  combined through a gap;
* :mod:`~companion.nav.potential.results`: :class:`FixTest`,
  :class:`PotentialPrediction`.

Known limits: the fit can settle in the broad basin at the α upper bound when
the true α is small (≲ 1.5 1/s), where the global valley is narrower than
the seeding grid; the multi-step terms trade the field's smoothing of noisy
fixes (which helps over 1-2 s with metre-level white noise) against its pull
on 5-20 s predictions (``fit_horizons_s`` sets the balance). On precise,
slowly varying fixes (RTK) the fit mostly drives G to its floor (the position
update does the tying, the field would only lag) and α is then immaterial.
The particle has no acceleration: at the onset of a turn or of the take-off
roll its one-step error grows faster than the calibration and the
acceleration estimate follow, so a manoeuvre's onset can cost a few rejected
fixes and a restart.

See ``docs/methods.md`` for the method notes.

References
----------
Grzegorzewski, "Navigating by a position potential in 3-D", Annual of
Navigation 9/2005: the potential, the corrected equation of motion, the
Bessel solution (4.55)-(4.62) corrected, the self-learning objective, the χ²
consistency test. Bessel asymptotics: Abramowitz & Stegun 9.2.28-9.2.31
(modulus and phase), 9.1.10-9.1.11 (small-argument series).
"""

from companion.nav.potential.bessel import (
    field_sums,
    propagate_axis,
    propagate_state,
    transition_axis,
)
from companion.nav.potential.combine import combine_predictions, combine_with_ins
from companion.nav.potential.config import PotentialConfig
from companion.nav.potential.filter import NAME_ALPHA, NAME_G, PotentialFilter
from companion.nav.potential.fit import (
    fit_pairs,
    replay_anchors,
    replay_cost,
    replay_state,
)
from companion.nav.potential.results import FixTest, PotentialPrediction
from companion.nav.potential.window import reset_velocity

__all__ = [
    "NAME_ALPHA",
    "NAME_G",
    "FixTest",
    "PotentialConfig",
    "PotentialFilter",
    "PotentialPrediction",
    "combine_predictions",
    "combine_with_ins",
    "field_sums",
    "fit_pairs",
    "propagate_axis",
    "propagate_state",
    "replay_anchors",
    "replay_cost",
    "replay_state",
    "reset_velocity",
    "transition_axis",
]
