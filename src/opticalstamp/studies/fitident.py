"""What a fit's images determine (issue 24): the degeneracies named, the directions of
the physical parameters they leave undetermined, on the Jacobian at the optimum."""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .fit import Layout

#: Singular value (of the column-normalised Jacobian, over the largest) below which a
#: direction is not seen by the images.
NULL_TOL = 1e-6
#: |correlation| above which two physical parameters are named as hard to tell apart.
CORR_TOL = 0.95


def degeneracies(jac: np.ndarray, lay: Layout, cov: np.ndarray) -> tuple[list[str], set[int]]:
    """Messages naming what the images cannot tell apart, and the physical columns of
    the combinations they do not see at all."""
    names = [lay.params[j].name for j in lay.free]
    nf = lay.n_free
    norms = np.linalg.norm(jac, axis=0)
    msgs, blind = [], set()
    for k in range(nf):
        if norms[k] == 0:
            msgs.append(
                f"{names[k]} is not constrained by these images (none changes with it): "
                f"fix it with --pin {names[k]}=..., or add an image that does (an edge for y)"
            )
            blind.add(k)
    use = norms > 0
    js = jac[:, use] / norms[use]
    _, sv, vt = np.linalg.svd(js, full_matrices=False)
    cols = np.flatnonzero(use)
    for s, v in zip(sv, vt, strict=True):
        if s > NULL_TOL * sv[0]:
            continue
        w = np.zeros(jac.shape[1])
        w[cols] = v
        phys = w[:nf]
        if np.linalg.norm(phys) < 1e-3:
            continue  # nuisance alone
        who = [k for k in range(nf) if abs(phys[k]) > 0.1 * np.abs(phys).max()]
        blind.update(who)
        listed = ", ".join(names[k] for k in who)
        chart = np.linalg.norm(w[nf:]) > 0.3
        why = " (together with the charts' positions)" if chart else ""
        msgs.append(
            f"{listed} are degenerate from these images{why}: one combination of them "
            f"changes no image; fix one with --pin {names[who[0]]}=..., or add an edge at "
            "another height"
        )
    sd = np.sqrt(np.clip(np.diag(cov)[:nf], 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov[:nf, :nf] / np.outer(sd, sd)
    for a in range(nf):
        for b in range(a + 1, nf):
            if a in blind or b in blind or not np.isfinite(corr[a, b]):
                continue
            if abs(corr[a, b]) > CORR_TOL:
                msgs.append(
                    f"{names[a]} and {names[b]} are hard to tell apart from these images "
                    f"(correlation {corr[a, b]:+.3f}): fix one with --pin {names[b]}=..., or "
                    "add an edge at another height"
                )
    return msgs, blind


def weak_directions(jac: np.ndarray, lay: Layout, scale2: float, undetermined: float) -> np.ndarray:
    """(m, free) directions of the physical parameters, in units of their assembly
    scales, that the images do not determine: the right singular vectors of the
    Jacobian's physical columns (each times its assembly scale, the nuisance columns
    projected out) whose standard error s / sigma exceeds ``undetermined`` scales."""
    nf = lay.n_free
    if nf == 0:
        return np.zeros((0, 0))
    scales = np.array([lay.params[j].scale for j in lay.free])
    jp, jn = jac[:, :nf] * scales, jac[:, nf:]
    if jn.shape[1]:
        q, _ = np.linalg.qr(jn)
        jp = jp - q @ (q.T @ jp)
    _, sv, vt = np.linalg.svd(jp, full_matrices=False)
    return vt[sv < np.sqrt(scale2) / undetermined]


def combination(v: np.ndarray, names: list[str]) -> dict[str, float]:
    """A held direction as {name: coefficient}, its largest coefficient positive."""
    v = v * np.sign(v[np.argmax(np.abs(v))])
    return {n: round(float(c), 3) for n, c in zip(names, v, strict=True) if abs(c) > 0.05}


def names_in(message: str, name: str) -> bool:
    """Whether ``message`` names the parameter ``name`` (as a whole word)."""
    return re.search(rf"(?<![\w.]){re.escape(name)}(?![\w]|\.\w)", message) is not None


def starts_apart(
    ends: np.ndarray, chi2s: np.ndarray, best: np.ndarray, sd: np.ndarray, delta: float
) -> dict[int, tuple[float, float]]:
    """Parameters the starts leave undetermined: {column: (lowest, highest)} of those
    that a start fitting the images as well as the best (chi2 within ``delta`` of it)
    puts more than 3 standard errors ``sd`` (the best's) from the best ``best``. The
    local errors cannot see another valley; the starts can.

    ``ends``: (starts, free) each start's minimum; ``chi2s``: their chi2.
    """
    good = ends[chi2s <= chi2s.min() + delta]
    far = np.abs(good - best) > 3 * np.where(np.isfinite(sd), sd, np.inf)
    return {
        int(k): (float(good[:, k].min()), float(good[:, k].max()))
        for k in np.flatnonzero(far.any(axis=0))
    }
