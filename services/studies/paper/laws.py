"""What each configuration of `sharedctl paper` runs, in the paper's equation numbers (docs/control.md §4–6).

The figures' captions, summary.json and summary.md take their descriptions from `describe`, and
nowhere else. `describe` reads the MachineController that ran, so a configuration whose wiring
no longer matches its description stops the command instead of mislabelling a figure.
"""
from __future__ import annotations

#: the sharing law and the machine law of each configuration (`sharedctl.simulator.make_controller`)
CONFIGURATIONS = {
    "ce": "(46) with (12)",
    "nce": "(46) with the composite law of §4.2 — (12)'s force with the prediction-error update on "
           "(14)–(15)'s filters",
    "of": "(47) with (25)–(29) on the observer (40)",
}

#: what the output-feedback configuration runs in the hazardous set (§4.3, §6 item 6), by the name of the
#: law its hazard role runs (MachineLaw.name)
OUTPUT_FEEDBACK_HAZARD = {
    "of-barrier": "its barrier form in the hazardous set (§4.3)",
    "ce": "(12) on the observer's v̂ in the hazardous set (§4.3)",
}


class ConfigurationMismatch(ValueError):
    """The controller that ran is not the one its description names."""


def describe(kind: str, controller) -> str:
    """The law a configuration ran: "ce" → "(46) with (12)", …; `controller` is the run's MachineController."""
    if kind not in CONFIGURATIONS:
        raise ConfigurationMismatch(f"unknown configuration {kind!r} (expected {', '.join(CONFIGURATIONS)})")
    if controller.tracking.name != kind:
        raise ConfigurationMismatch(f"configuration {kind!r} ran the tracking law {controller.tracking.name!r}")
    law = CONFIGURATIONS[kind]
    hazard = controller.hazard.name if controller.hazard is not controller.tracking else None
    if kind != "of":
        if hazard is not None:
            raise ConfigurationMismatch(f"configuration {kind!r} runs {hazard!r} in the hazardous set, not its own law")
        return law
    if hazard not in OUTPUT_FEEDBACK_HAZARD:
        raise ConfigurationMismatch(f"configuration 'of' runs {hazard or 'its tracking law'!r} in the hazardous set; "
                                    f"described are {', '.join(OUTPUT_FEEDBACK_HAZARD)}")
    return f"{law}, {OUTPUT_FEEDBACK_HAZARD[hazard]}"
