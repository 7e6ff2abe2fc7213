"""The model of a solid texture."""
