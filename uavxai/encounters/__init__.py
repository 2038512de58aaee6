"""Statistical airspace encounters: the MIT LL uncorrelated encounter model (docs/encounters.md)."""
