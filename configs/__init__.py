"""Render presets shipped with motion (ci-smoke, preview, final) and farm settings."""
