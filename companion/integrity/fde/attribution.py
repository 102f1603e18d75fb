"""Attribution: which receiver a failed test blames, or none (the fault stays unresolved).

* A failed **innovation** test blames its receiver unless the navigator itself
  may be off: a fault is already unresolved (the navigator may have absorbed
  it), the fix agrees with another receiver's, or, with several receivers, its
  NIS does not exceed each other's by the F(dof, dof) quantile at
  ``attribution_error_prob`` (a navigator pulled by a faulty receiver gives
  comparable innovations to all).
* A separation that fails against a **reference** blames the receiver, when the
  reference may be trusted: while receivers disagree, a reference anchored less
  than one separation window before the disagreement was detected may carry the
  fault (it was anchored from the navigator fusing the faulty receiver) and does
  not count.
* Two **receivers** that disagree are told apart by their separations from
  third solutions (other receivers, references): the one that fails a test
  against a third solution while the other passes them all is the culprit;
  otherwise nothing tells until the evidence comes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from scipy.stats import f as f_dist

from companion.integrity.config import IntegrityConfig
from companion.integrity.fde.pairs import REF_PREFIX, PairKey, PairSeparations
from companion.integrity.fde.receivers import ReceiverState, is_excluded
from companion.integrity.fde.separation import SeparationResult

NIS_FLOOR = 1e-6
"""Lower bound of a NIS in the attribution ratio (a perfect fix must not divide by zero)."""


class Attribution:
    """The attribution rules over the receivers' states and the pairs' latest results.

    ``receivers`` and ``pairs`` are the fault detector's own (read, not changed).
    ``episode_start_s``: when the current disagreement between receivers was first
    detected (None: none); the detector sets and clears it.
    """

    def __init__(
        self,
        config: IntegrityConfig,
        receivers: Mapping[int, ReceiverState],
        pairs: PairSeparations,
    ) -> None:
        self.config = config
        self.receivers = receivers
        self.pairs = pairs
        # F(3, 3): the fix-level tests are 3-dof position tests
        self.f_ratio = float(f_dist.isf(config.attribution_error_prob, 3, 3))
        self.episode_start_s: float | None = None

    def reset(self) -> None:
        """Forget the disagreement episode."""
        self.episode_start_s = None

    def innovation_is_own(
        self, rid: int, t: float, this_epoch: Mapping[PairKey, SeparationResult]
    ) -> bool:
        """Is a failed innovation test of ``rid`` its own fault, not the navigator's?

        (The caller has ruled out an unresolved fault.)

        * Not when this fix agrees (separation snapshot, ``this_epoch``) with another
          receiver's: then the navigator is what is off.
        * With no other receiver recently tested against the same navigator, yes.
        * Otherwise only when its NIS exceeds each other's by the F(dof, dof)
          quantile at ``attribution_error_prob``.
        """
        receivers = self.receivers
        mine = receivers[rid].last_nis
        for qid, other in receivers.items():
            if qid == rid:
                continue
            lo, hi = sorted((rid, qid))
            pair = this_epoch.get((f"rx{lo}", f"rx{hi}"))
            if pair is not None and not pair.snapshot_failed:
                return False  # it agrees with another receiver: the navigator is off
            if t - other.last_nis_t_s > self.config.pair_max_dt_s:
                continue
            if not mine > self.f_ratio * max(other.last_nis, NIS_FLOOR):
                return False
        return True

    def reference_trusted(self, key: PairKey) -> bool:
        """May the reference of ``key`` blame a receiver?

        A reference anchored from the navigator while it fused a faulty receiver carries
        that receiver's fault: against the good receiver it fails. So while receivers
        disagree, a reference only counts if it was anchored at least one separation
        window before the disagreement was first detected (the window tests look back
        that far: the fault may have been present all that time). Without a receiver
        disagreement (one receiver), every reference counts.
        """
        start = self.episode_start_s
        anchor = self.pairs.ref_anchor_t_s.get(key)
        if start is None or anchor is None:
            return True
        return anchor <= start - self.config.separation_window_s

    def arbitrate(
        self, a: int, b: int, key: PairKey, culprits: set[int], now_s: float | None
    ) -> int | None:
        """Which of two disagreeing receivers is faulty, or None when nothing tells.

        A receiver already blamed or excluded is the culprit. Otherwise each one's latest
        separations (within one separation window of ``now_s``) from third solutions
        (other receivers, references) are scored by their largest test statistic over
        its threshold (snapshot, slope, residual): the culprit is the one that fails a
        test against a third solution (score > 1) while the other passes them all
        (score <= 1).
        """
        for cid in (a, b):
            if cid in culprits or is_excluded(self.receivers, cid, now_s):
                return cid
        now = now_s if now_s is not None else -math.inf
        horizon = self.config.separation_window_s
        score: dict[int, list[float]] = {a: [], b: []}
        for k, res in self.pairs.latest.items():
            if k == key or now - res.t_s > horizon:
                continue
            if k[1].startswith(REF_PREFIX) and not self.reference_trusted(k):
                continue
            for cid in (a, b):
                other = b if cid == a else a
                if f"rx{cid}" in k and f"rx{other}" not in k:
                    score[cid].append(_score(res))
        if not score[a] or not score[b]:
            return None
        sa, sb = max(score[a]), max(score[b])
        if sa > 1.0 >= sb:
            return a
        if sb > 1.0 >= sa:
            return b
        return None


def _score(res: SeparationResult) -> float:
    """The largest of a separation's test statistics over their thresholds (> 1 fails)."""
    ratios = [res.snapshot_stat / res.snapshot_threshold, res.slope_ratio, res.rss_ratio]
    return max(r for r in ratios if math.isfinite(r))
