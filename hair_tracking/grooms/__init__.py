"""Grooms from files: the readers of the strand formats people have, resampling, fitting onto
the head and the choice of guides among the imported strands (docs/grooms.md)."""
