"""Reporting: the report's reference tables, validation cases and
runner, figures."""
