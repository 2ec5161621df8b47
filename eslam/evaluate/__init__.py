"""Metrics on arrays and files only: never imports the field or the renderer."""
