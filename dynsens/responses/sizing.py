r"""Aggregates over time and components for sizing: sampled maximum/minimum and KS.

Every aggregate reads one or more outputs, picks components of each and maps every picked
component v through one or more signed scalings c (a *side*): g = c·v.  A stress ratio in
tension and compression, for instance, uses the two sides c = 1/σ_t and c = −1/σ_c of the
same stress; ``absolute`` uses c = ±1 (so that max g = max |v|).  The aggregate of all g over
all instants of the run is then

* ``max``: the sampled maximum g* = max_k g_k, with the gradient of its active sample ∇g_{k*}
  (exact where the maximum is attained by one sample; a kink where two samples tie);
* ``ks``: the Kreisselmeier–Steinhauser function KS = g* + (1/ρ) ln Σ_k exp(ρ(g_k − g*)) with
  ∇KS = Σ_k w_k ∇g_k, softmax weights w_k.  ρ carries the inverse unit of g; g* ≤ KS ≤
  g* + ln(N)/ρ for N samples, so ln(N)/ρ bounds the over-estimate.  The sampled maximum is
  reported beside the KS value, with a warning when ln(N)/ρ exceeds ``KS_WARN_FRACTION``
  of |KS|.

``min`` and a lower KS (``sense = −1``) aggregate −g and negate the result.

:class:`MagnitudeAggregate` aggregates lengths instead: g = |v_G|·c of groups G of components
(a node's translation vector; a one-component group is the absolute value, both signs), with
|v| = √(Σ v²) written so that a complex step passes through it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .base import FinishContext, OutputTrace, Response, ResponseValue, Samples

KS_WARN_FRACTION = 0.03  # ln(N)/ρ above this share of |KS| is reported as a warning


@dataclass(frozen=True)
class Term:
    """Components ``components`` (k,) of output ``output_id``, each mapped through the rows of
    ``sides`` (S, k): g = sides[s] · v for every side s."""

    output_id: int
    components: np.ndarray
    sides: np.ndarray


class Aggregate(Response):
    """Sampled maximum (``how='max'``) or KS (``how='ks'``) of g over time and components;
    ``sense=-1`` turns either into the corresponding minimum."""

    def __init__(self, name: str, terms: tuple[Term, ...], how: str, unit: str, *,
                 sense: int = 1, rho: float | None = None):
        if how not in ("max", "ks") or sense not in (1, -1) or (how == "ks" and not rho):
            raise ValueError(f"invalid aggregate {how!r}, sense {sense}, rho {rho}")
        self.name, self.unit = name, unit
        self.terms = terms
        self.output_ids = tuple(dict.fromkeys(t.output_id for t in terms))
        self.how, self.sense, self.rho = how, sense, rho
        self._best: Any = None               # the sampled maximum of sense·g so far
        self._best_grad: np.ndarray | None = None
        self._sum: Any = 0.0                  # KS: Σ exp(ρ(g_k − g*))
        self._wgrad: np.ndarray | None = None  # KS: Σ exp(ρ(g_k − g*)) ∇g_k
        self._count = 0

    def _gather(self, smp: Samples) -> tuple[np.ndarray, np.ndarray | None]:
        """sense·g of all samples of a block, (N,), and their gradients (N, m) or None."""
        vals: list[np.ndarray] = []
        grads: list[np.ndarray | None] = []
        for t in self.terms:
            v = smp.value[t.output_id][:, t.components]            # (K, k)
            g = smp.grad[t.output_id]
            g = None if g is None else g[:, t.components]          # (K, k, m)
            for side in t.sides:
                c = self.sense * side
                vals.append(c * v)
                grads.append(None if g is None else c[None, :, None] * g)
        value = np.concatenate(vals, axis=1).ravel()
        if any(g is None for g in grads):
            return value, None
        grad = np.concatenate([g for g in grads if g is not None], axis=1)
        return value, grad.reshape(value.size, grad.shape[-1])

    def feed(self, samples: Samples) -> None:
        v, G = self._gather(samples)
        self._count += v.size
        k = int(np.argmax(v.real))
        if self._best is None or v[k].real > np.real(self._best):
            if self._best is not None and self.how == "ks":
                factor = np.exp(self.rho * (self._best - v[k]))
                self._sum = self._sum * factor
                if self._wgrad is not None:
                    self._wgrad = self._wgrad * factor
            self._best = v[k]
            self._best_grad = None if G is None else G[k]
        if self.how == "ks":
            w = np.exp(self.rho * (v - self._best))
            self._sum = self._sum + np.sum(w)
            if G is not None:
                contrib = w @ G
                self._wgrad = contrib if self._wgrad is None else self._wgrad + contrib

    def adjoint_unsupported(self) -> str | None:
        return None

    def _sample_weights(self, g: np.ndarray) -> np.ndarray:
        """dJ/d(sense·g) of every sample g (K, C): the final softmax weights (KS) or 1 at the
        active sample (max: the first maximum in (instant, column) order, as feed keeps it)."""
        if self.how == "max":
            W = np.zeros_like(g)
            W[np.unravel_index(int(np.argmax(g)), g.shape)] = 1.0
            return W
        return np.exp(self.rho * (g - np.real(self._best))) / np.real(self._sum)

    def adjoint_weights(self, trace: OutputTrace) -> dict[Any, Any] | None:
        """Weights of the outputs' gradients: the sample weights times ∂(s·g)/∂v = side (the
        sense cancels); the same sums :meth:`feed` formed."""
        cols = [(t.output_id, t.components, self.sense * side) for t in self.terms for side in t.sides]
        g = np.concatenate([c * np.real(trace.value[o][:, comp]) for o, comp, c in cols], axis=1)   # (K, C)
        W = self._sample_weights(g)
        out: dict[Any, Any] = {o: np.zeros(np.shape(trace.value[o])) for o in self.output_ids}
        start = 0
        for o, comp, c in cols:
            n = len(comp)
            np.add.at(out[o].T, comp, (W[:, start:start + n] * (self.sense * c)).T)   # columns comp (repeats add)
            start += n
        return out

    def finish(self, ctx: FinishContext) -> ResponseValue:
        if self._best is None:
            return ResponseValue(np.nan, None, self.unit, missing="no instant was sampled")
        s = self.sense
        sampled = s * self._best
        if self.how == "max":
            grad = None if self._best_grad is None else s * self._best_grad
            return ResponseValue(sampled, grad, self.unit)
        value = s * (self._best + np.log(self._sum) / self.rho)
        grad = None if self._wgrad is None else s * self._wgrad / self._sum
        bound = float(np.log(self._count) / self.rho)
        extra: dict[str, Any] = {"sampled_max" if s > 0 else "sampled_min": float(np.real(sampled)),
                                 "samples": self._count, "ks_gap_bound": bound}
        scale = abs(float(np.real(value)))
        if bound > KS_WARN_FRACTION * scale:
            share = f"{100 * bound / scale:.0f} %" if scale > 0 else "more than the value itself"
            extra["warning"] = (f"KS may lie beyond the sampled {'maximum' if s > 0 else 'minimum'} by up to "
                                f"ln(N)/rho = {bound:.4g} ({share} of the value; N = {self._count}): "
                                f"raise rho or use type 'max'")
        return ResponseValue(value, grad, self.unit, extra=extra)


@dataclass(frozen=True)
class GroupTerm:
    """Groups of components of output ``output_id``, ``groups`` (G, d): g_j = scale·|v[groups[j]]|."""

    output_id: int
    groups: np.ndarray
    scale: float


def _lengths(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """|v| = √(Σ_c v_c²) over the last axis of v (..., d) and ∂|v|/∂v (..., d); zero where
    v = 0 (there |v| has no derivative; the subgradient 0 is taken)."""
    sq = np.sum(v * v, axis=-1)
    zero = np.real(sq) <= 0.0
    n = np.sqrt(np.where(zero, 1.0, sq))
    return np.where(zero, 0.0, n), np.where(zero[..., None], 0.0, v / n[..., None])


class MagnitudeAggregate(Aggregate):
    """Sampled maximum or KS of lengths g = scale·|v_G| over groups, instants and outputs."""

    def __init__(self, name: str, terms: tuple[GroupTerm, ...], how: str, unit: str, *,
                 rho: float | None = None):
        super().__init__(name, (), how, unit, rho=rho)
        self.group_terms = terms
        self.output_ids = tuple(dict.fromkeys(t.output_id for t in terms))

    def _gather(self, smp: Samples) -> tuple[np.ndarray, np.ndarray | None]:
        vals, grads = [], []
        for t in self.group_terms:
            length, dlen = _lengths(smp.value[t.output_id][:, t.groups])      # (K, G), (K, G, d)
            vals.append(t.scale * length)
            g = smp.grad[t.output_id]
            grads.append(None if g is None else t.scale * np.einsum("kgd,kgdm->kgm", dlen, g[:, t.groups]))
        value = np.concatenate(vals, axis=1).ravel()
        if any(g is None for g in grads):
            return value, None
        grad = np.concatenate([g for g in grads if g is not None], axis=1)
        return value, grad.reshape(value.size, grad.shape[-1])

    def adjoint_weights(self, trace: OutputTrace) -> dict[Any, Any] | None:
        """The sample weights times ∂g_j/∂v_c = scale·v_c/|v| of the group's components."""
        parts = [_lengths(np.real(trace.value[t.output_id][:, t.groups])) for t in self.group_terms]
        W = self._sample_weights(np.concatenate([t.scale * n for t, (n, _) in zip(self.group_terms, parts)], axis=1))
        out: dict[Any, Any] = {o: np.zeros(np.shape(trace.value[o])) for o in self.output_ids}
        start = 0
        for t, (_, dlen) in zip(self.group_terms, parts):
            G, d = t.groups.shape
            w = (W[:, start:start + G, None] * t.scale * dlen).reshape(len(W), G * d)   # (K, G·d)
            np.add.at(out[t.output_id].T, t.groups.ravel(), w.T)
            start += G
        return out


@dataclass(frozen=True)
class FormTerm:
    """Linear forms of members' components: the outputs' components ``parts`` ((output_id,
    components (k_o,)), …) side by side give the columns of V (K, n); member i reads the columns
    ``columns[i]`` (k,) and its forms are ``forms[i]`` (F, k): g_if = forms[i] · V[columns[i]]."""

    parts: tuple[tuple[int, np.ndarray], ...]
    columns: np.ndarray
    forms: np.ndarray


class FormAggregate(Aggregate):
    """Sampled maximum or KS of linear forms g_if of the members' components over forms,
    members and instants (e.g. the beam-column interaction of :mod:`dynsens.responses.member_stability`,
    a maximum of linear forms itself)."""

    def __init__(self, name: str, term: FormTerm, how: str, unit: str, *, rho: float | None = None):
        super().__init__(name, (), how, unit, rho=rho)
        self.form_term = term
        self.output_ids = tuple(dict.fromkeys(o for o, _ in term.parts))

    def _columns(self, values: dict[int, Any]) -> np.ndarray:
        """V (K, n, ...) of one block: the parts' components side by side."""
        return np.concatenate([values[o][:, c] for o, c in self.form_term.parts], axis=1)

    def _gather(self, smp: Samples) -> tuple[np.ndarray, np.ndarray | None]:
        t = self.form_term
        V = self._columns(smp.value)[:, t.columns]                           # (K, n_m, k)
        value = np.einsum("Kmk,mfk->Kmf", V, t.forms).ravel()
        if any(smp.grad[o] is None for o, _ in t.parts):
            return value, None
        G = self._columns(smp.grad)[:, t.columns]                            # (K, n_m, k, d)
        return value, np.einsum("Kmkd,mfk->Kmfd", G, t.forms).reshape(value.size, G.shape[-1])

    def adjoint_weights(self, trace: OutputTrace) -> dict[Any, Any] | None:
        """The sample weights times ∂g_if/∂V = forms[i, f] at the member's columns."""
        t = self.form_term
        V = np.real(self._columns(trace.value))                              # (K, n)
        g = np.einsum("Kmk,mfk->Kmf", V[:, t.columns], t.forms)
        W = self._sample_weights(g.reshape(len(V), -1)).reshape(g.shape)
        dV = np.zeros_like(V)
        np.add.at(dV.T, t.columns.ravel(), np.einsum("Kmf,mfk->Kmk", W, t.forms).reshape(len(V), -1).T)
        out: dict[Any, Any] = {o: np.zeros(np.shape(trace.value[o])) for o in self.output_ids}
        start = 0
        for o, comp in t.parts:
            np.add.at(out[o].T, comp, dV[:, start:start + len(comp)].T)
            start += len(comp)
        return out
