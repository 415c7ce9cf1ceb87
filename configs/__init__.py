"""The shipped configuration presets (YAML), installed as package data."""
