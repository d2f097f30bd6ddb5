"""Named errors of the engine. Every message says what is wrong and what to do about it."""


class SceneError(ValueError):
    """A scene (or a model setting) is invalid.

    ``field`` is the dotted path of the offending value (``boxes[3].extents_m``), so a caller can
    point at it; the message repeats it and says what is allowed.
    """

    def __init__(self, field: str, problem: str):
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}")


class ConfigError(ValueError):
    """A model, query or simulation setting is out of range."""

    def __init__(self, field: str, problem: str):
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}")


class PhysicsError(RuntimeError):
    """One rollout produced non-finite or impossible states (the solver diverged).

    Raised inside a rollout and turned into a counted ``failed_samples`` entry by the sampler;
    it never ends a prediction on its own.
    """
