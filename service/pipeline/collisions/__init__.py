"""Collision handling: the stages that take the fitted garments to meshes that cross nothing."""
