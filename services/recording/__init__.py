"""Flight recorder: MCAP recordings of every Zenoh message and candump logs of the CAN bus; replay and plots."""
