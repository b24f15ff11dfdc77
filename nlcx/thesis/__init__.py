"""The thesis reproduced: its numbers (data/, transcribed extracts), experiments and claims."""
