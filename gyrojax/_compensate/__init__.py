"""Scale-factor compensation: polynomial (seed 000's baseline), composite (seed 000), model-based."""
