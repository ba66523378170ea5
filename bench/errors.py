"""Errors the harness reports to users as one line, never as a traceback."""


class ConfigError(ValueError):
    """Bad user input: a sweep file, a parameter, a command-line option.

    The message names the field and the problem, e.g.
    ``methods[1].params.window: expected int >= 3, got -2``. The CLI prefixes
    it with the file name, prints it on one line and exits with code 2.
    """

    def __init__(self, field: str, problem: str):
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}" if field else problem)

    def within(self, prefix: str) -> "ConfigError":
        """The same error with its field placed under ``prefix``."""
        field = f"{prefix}.{self.field}" if self.field else prefix
        return ConfigError(field, self.problem)
