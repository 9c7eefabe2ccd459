"""Where lambda_hap L_hap pulls on the actor (environment v6, the mechanism table; docs/
FINDINGS.md "Protocol v6", rule 7), for `distgprl.agents.sac.RegularisedSAC.
actor_loss_gradient_norms`.

L_hap is hinged (`distgprl.safety.hap_loss`): a query point inside C_safe has L_hap = 0 and
no gradient, one outside has both positive. Every query position depends on every adapted
via-point through the GP's read-out (its weights are nowhere exactly 0), so a sample's L_hap
gradient on the action is exactly 0 where, and only where, all its query points lie inside
C_safe, i.e. where its own L_hap = 0 (tests/agents/test_sac.py checks this against each
sample's L_hap on real observations). The samples with L_hap > 0 are therefore those whose
gradient row is nonzero.
"""

from __future__ import annotations

import torch

__all__ = ["active_hap_norms"]


def active_hap_norms(hap_gradient: torch.Tensor, batch_size: int) -> dict[str, float]:
    """``hap_active_fraction``, the share of the batch's samples whose L_hap > 0 (outside
    C_safe: a nonzero gradient row, module docstring), and ``grad_hap_active``, the mean over
    those samples of lambda_hap L_hap's per-sample gradient norm on the action (raw action
    units), absent where no sample is active.

    Args:
        hap_gradient: d (lambda_hap L_hap) / d a of the batch-mean loss, shape (B, A)
            (``ActorRegulariser.term_gradients(...)["l_hap"]``).
        batch_size: B; the batch-mean loss's gradient times B is the per-sample gradient.
    """
    norms = (hap_gradient * batch_size).norm(dim=1)
    active = norms > 0.0
    out = {"hap_active_fraction": float(active.double().mean())}
    if bool(active.any()):
        out["grad_hap_active"] = float(norms[active].mean())
    return out
