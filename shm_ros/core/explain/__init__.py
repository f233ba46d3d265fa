"""Explain: where the nominal model and the recordings disagree, which physics it is missing, and how
much better the model fits once that physics is added (docs/interfaces.md §5, docs/explain.md).

Stages, one module each: :mod:`.groups` (parameter groups of the analysis model: span stiffness,
bearings, masses, dampers), :mod:`.surrogate` (modal properties per window when groups change with
the window's covariates, cheaply and checked against the exact model), :mod:`.likelihood` (the
misfit of log-frequencies with per-mode model-form offsets and noise integrated out), :mod:`.locate`
(residual analysis: what the misfit co-varies with and where it acts, which candidates to try),
:mod:`.candidates` (the library of candidate physics, one small file each, behind one interface),
:mod:`.fit` (fit a candidate, its evidence by two estimators), :mod:`.select` (threshold, held-out
windows, candidates the data cannot tell apart), :mod:`.explain` (the whole chain -> :class:`Verdict`).
"""
