"""`sharedctl bench`: control-step, loop, latency, bus-load, CPU and batched-simulator measurements."""
