"""Controllers and the gain schedules of the PID controller, registered by name."""
