"""The robot process, `sharedctl robot` (see docs/services.md).

* `axis.py`       one simulated ODrive axis: states, modes, errors, watchdog, Get_* replies (pure)
* `plant.py`      true dynamics: omni3 model + wheel friction, torque and speed limits, RK4;
                  the `[robot_sim]` settings (pure)
* `simulation.py` three axes on the plant, cyclic frame schedule, time from the caller (pure)
* `process.py`    the I/O shell: CAN receive/send, Zenoh ground truth and liveliness, 1 kHz loop
* `command.py`    the command line
"""
