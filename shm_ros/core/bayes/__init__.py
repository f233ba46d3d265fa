"""Bayesian model updating: priors, likelihoods, samplers, evidence, diagnostics.

The one-call entry is :func:`shm_ros.core.bayes.update.update`; everything else is a small piece it
assembles. Heavy imports (arviz, dynesty) are kept inside the functions that need them.
"""
