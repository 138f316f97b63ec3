"""Many robots stepped together: the closed loop (plant, machine law, sharing) vectorised over a batch."""
