"""Accelerations under the measured input: one record, or several events sharing the error model."""

from __future__ import annotations

from shm_ros.core.bayes.records import JointTimeDomainLikelihood, RecordSet
from shm_ros.core.bayes.timedomain import AccelerationRecord, TimeDomainLikelihood

from .base import LIKELIHOODS, Likelihood, LikelihoodInputs, LikelihoodKind, LikelihoodName


@LIKELIHOODS.register(LikelihoodName.TIME)
class Time(LikelihoodKind):
    modal = False

    def build(self, inputs: LikelihoodInputs) -> Likelihood:
        c, data = inputs.config, inputs.data
        if isinstance(data, RecordSet):
            return JointTimeDomainLikelihood(inputs.model, data, variance=c.variance, error_prior_shape=c.ig_shape,
                                             ar_order=c.residual_ar_order,
                                             per_record=c.variance_per_event)
        if not isinstance(data, AccelerationRecord):
            raise TypeError("likelihood 'time' needs an AccelerationRecord (input and output "
                            "accelerations), not modal data")
        return TimeDomainLikelihood(inputs.model, data, variance=c.variance, error_prior_shape=c.ig_shape,
                                    ar_order=c.residual_ar_order)
