"""servo stage."""
