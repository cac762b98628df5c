"""The time loop: the stepper, step sequences, records, run checks and the runaway monitor."""
