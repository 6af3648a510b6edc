"""Control rigs seen by the solver: the body's hierarchy over deform bones, whatever they hang from."""
