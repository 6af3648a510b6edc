"""Long computations as step generators: they yield progress in [0, 1] and return a result,
so the UI can run them in chunks (and cancel them) while batch jobs just run them through."""


def run_to_end(steps):
    """Drive a step generator to its end and return its result."""
    while True:
        try:
            next(steps)
        except StopIteration as done:
            return done.value
