"""robots stage."""
