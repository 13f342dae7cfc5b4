"""Generator-only code of the D-H presets (scripts/gen_presets.py) and its tests."""
