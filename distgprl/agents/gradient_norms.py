"""Where lambda_hap L_hap pulls on the actor (the mechanism table), for
`distgprl.agents.sac.RegularisedSAC.actor_loss_gradient_norms`.

L_hap (Eq. hap_compact, `distgprl.safety.hap_loss`) is a soft-min distance to C_safe: every
query pulls towards its nearest safe points, inside C_safe too. A sample is *outside* C_safe
where one of its query points has a soft-min above the largest soft-min anywhere inside a
fully safe grid (`HapPrior.outside_threshold`; with the hinged variant, where its L_hap > 0).
The mechanism table reports the share of such samples and the pull on them.
"""

from __future__ import annotations

import torch

__all__ = ["active_hap_norms"]


def active_hap_norms(
    hap_gradient: torch.Tensor, batch_size: int, outside: torch.Tensor | None = None
) -> dict[str, float]:
    """``hap_active_fraction``, the share of the batch's samples outside C_safe, and
    ``grad_hap_active``, the mean over those samples of lambda_hap L_hap's per-sample gradient
    norm on the action (raw action units), absent where no sample is outside.

    Args:
        hap_gradient: d (lambda_hap L_hap) / d a of the batch-mean loss, shape (B, A)
            (``ActorRegulariser.term_gradients(...)["l_hap"]``).
        batch_size: B; the batch-mean loss's gradient times B is the per-sample gradient.
        outside: shape (B,), bool: which samples have a query outside C_safe
            (``term_gradients(...)["hap_outside"]``); None: those with a nonzero gradient
            row (exact for the hinged variant, whose gradient is 0 inside C_safe).
    """
    norms = (hap_gradient * batch_size).norm(dim=1)
    active = norms > 0.0 if outside is None else outside.to(torch.bool)
    out = {"hap_active_fraction": float(active.double().mean())}
    if bool(active.any()):
        out["grad_hap_active"] = float(norms[active].mean())
    return out
