"""spacepose package part."""
