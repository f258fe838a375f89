"""Bundled scenes, shipped as package data (see pyproject.toml)."""
