"""`AbstractResult`: what every result of gyrojax offers an output format (a kind name, a JSON form and terminal
text)."""

from typing import Any, ClassVar, Protocol, runtime_checkable


@runtime_checkable
class AbstractResult(Protocol):
    """The contract of a result (`Fit`, `PopulationFit`, `Diagnosis`, `Plan`, `RateTablePlan`,
    `CompensationResult`, `MetricsReport`, ...): what an output format reads.

    A protocol rather than an abstract `eqx.Module`: every gyrojax result is a final equinox module (its records
    typed modules, built by keyword; `tests/test_result_convention.py`), and a user's result need only define:

    - `kind`: a class-level name, e.g. `"fit"` or `"diagnosis"` (a generic rendering's title);
    - `to_json()`: the result as JSON-safe Python (dicts, lists, strings, finite floats, ints, booleans, None;
      None for a number the data do not give, with the reason beside it), the object the command line's
      `--json` file holds;
    - `summary()`: a few lines of text for a terminal.

    A result may also define `markdown()`, its own Markdown report (`Diagnosis` does); the `markdown` format then
    writes that instead of its generic rendering.
    """

    kind: ClassVar[str]

    def to_json(self) -> Any: ...

    def summary(self) -> str: ...
