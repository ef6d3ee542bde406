"""Diagnosis: what the simulation gets wrong, the cause, and the model extension that fixes it."""
