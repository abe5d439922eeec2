"""Franka FR3 / Panda over libfranka (FCI): driver, codec, emulator (docs/franka.md)."""
