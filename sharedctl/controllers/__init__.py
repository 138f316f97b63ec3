"""Machine controllers, one law per constraint group (paper Section 3)."""
from .adaptation import Adaptation
from .base import LawOutput, MachineLaw
from .certainty_equivalent import CertaintyEquivalentLaw
from .composite_adaptive import CompositeAdaptiveLaw
from .non_certainty_equivalent import NonCertaintyEquivalentLaw
from .output_feedback import OutputFeedbackLaw
from .output_feedback_barrier import OutputFeedbackBarrierLaw
from .observer import VelocityObserver

__all__ = [
    "Adaptation",
    "LawOutput",
    "MachineLaw",
    "CertaintyEquivalentLaw",
    "CompositeAdaptiveLaw",
    "NonCertaintyEquivalentLaw",
    "OutputFeedbackLaw",
    "OutputFeedbackBarrierLaw",
    "VelocityObserver",
]
