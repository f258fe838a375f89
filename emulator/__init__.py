"""lrf-emulator: virtual laser range finders in a smoky 3D scene."""
