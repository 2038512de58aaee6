"""Explanations of avoidance decisions, read off the search tree."""
