"""The simulated gearhead DC servo plant (pure core)."""
