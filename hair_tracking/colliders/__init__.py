"""Colliders: the shapes the hair is kept out of, and the one contact model every guide solver
and ghost tracker applies (see ``docs/colliders.md``)."""
