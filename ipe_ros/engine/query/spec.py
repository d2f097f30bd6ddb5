"""Which queries a prediction answers and their parameters (:class:`QuerySpec`), and the registry
of queries by name that it checks names against.

The registry is filled by ``engine.query`` (each built-in query module's ``QUERY``) and by
:func:`register` for a query added at run time; it holds no query code itself, so the query modules
can read a QuerySpec without an import circle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..checks import positive
from ..errors import ConfigError, shown

#: every registered query (an ``engine.query.base.Query``) by name, in the order answers list them
QUERIES: dict[str, Any] = {}


def register(query: Any) -> Any:
    """Add a query to the registry (its ``name`` must be new); returns it. A name is then accepted by
    QuerySpec, and the query's ``read`` and ``aggregate`` run wherever it is asked."""
    name = getattr(query, "name", None)
    if not isinstance(name, str) or not name.isidentifier():
        raise ConfigError("query.name", f"must be an identifier, got {shown(name)}")
    if name in QUERIES:
        raise ConfigError("query.name", f"{name!r} is registered already; choose another name")
    QUERIES[name] = query
    return query


def unregister(name: str) -> None:
    """Remove a query registered at run time (a test's, a plugin's); the built-in ones stay."""
    query = QUERIES.get(name)
    if query is not None and type(query).__module__.startswith(BUILT_IN_PACKAGE):
        raise ConfigError("query.name", f"{name!r} is built in; it cannot be unregistered")
    QUERIES.pop(name, None)


#: where the built-in queries live; a query of any other module was registered as a plugin
BUILT_IN_PACKAGE = __name__.rsplit(".", 1)[0] + "."


def plugin_modules() -> tuple[str, ...]:
    """The modules of the queries registered at run time, which worker processes import so that
    they know those queries too (a module registers its query when imported); ``__main__`` is
    left out (a worker cannot import it: define queries in an importable module)."""
    modules = {type(q).__module__ for q in QUERIES.values()}
    return tuple(sorted(m for m in modules if not m.startswith(BUILT_IN_PACKAGE) and m != "__main__"))


@dataclass(frozen=True)
class QuerySpec:
    """Which queries to compute and their thresholds.

    fall_threshold_fraction: an object has fallen when its centre's z dropped by more than this
        fraction of its own smallest extent. The default 0.125 is the paper's "0.025 unit" read in
        the stimulus files' units (0.025 m on 0.2 m blocks).
    A query's own parameters (the bump query's group, the rest query's reading of rest, a plugin's)
    are its ``Parameters`` (``parameters``, ``parameters_of``).
    """

    queries: frozenset[str] = frozenset({"fall"})
    fall_threshold_fraction: float = 0.125
    #: the contact query's pairs (A, B): B may be "support"
    contact_pairs: tuple[tuple[str, str], ...] = ()
    #: (query name, its ``Parameters`` instance) for asked queries that declare parameters and were
    #: given some; a query not listed reads its defaults (``parameters_of``)
    parameters: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        check_names(self.queries)
        check_parameters(self.parameters, self.queries)
        positive(self.fall_threshold_fraction, "fall_threshold_fraction")
        if not isinstance(self.contact_pairs, tuple) or not all(
                isinstance(pair, tuple) and len(pair) == 2 and all(isinstance(n, str) and n for n in pair)
                for pair in self.contact_pairs):
            raise ConfigError("contact", "pairs must be a tuple of (A, B) object names")
        if self.contact_pairs and "contact" not in self.queries:
            raise ConfigError("contact", "pairs were given but the contact query was not asked; add contact "
                                         "to the queries")
        if "contact" in self.queries and not self.contact_pairs:
            raise ConfigError("contact", "the contact query needs pairs to watch: give A:B (B may be support), "
                                         "or drop contact from the queries")
        for a, b in self.contact_pairs:  # what no scene can answer, refused before any scene arrives
            if a == b:
                raise ConfigError("contact", f"{a}:{b}: an object always touches itself; name two")
        if len(set(self.contact_pairs)) != len(self.contact_pairs):
            raise ConfigError("contact", "a pair is asked twice; ask each once")

    def wants(self, name: str) -> bool:
        return name in self.queries

    def parameters_of(self, name: str) -> Any:
        """Query ``name``'s parameters: as given, or its ``Parameters`` defaults."""
        for query, given in self.parameters:
            if query == name:
                return given
        cls = getattr(QUERIES.get(name), "Parameters", None)
        if cls is None:
            raise ConfigError("queries", f"the {name} query has no parameters")
        return cls()


def check_parameters(parameters, queries: frozenset[str]) -> None:
    """Each entry names an asked query once, with an instance of that query's ``Parameters``."""
    if not isinstance(parameters, tuple) or not all(isinstance(p, tuple) and len(p) == 2 for p in parameters):
        raise ConfigError("parameters", "must be a tuple of (query name, its Parameters) pairs")
    names = [name for name, _ in parameters]
    if len(set(names)) != len(names):
        raise ConfigError("parameters", "a query's parameters are given twice; give them once")
    for name, given in parameters:
        if name not in queries:
            raise ConfigError("parameters", f"parameters for {shown(name)}, which is not asked; ask it or drop them")
        cls = getattr(QUERIES[name], "Parameters", None)
        if cls is None or type(given) is not cls:
            raise ConfigError("parameters", f"the {name} query's parameters must be its Parameters, got "
                                            f"{type(given).__name__}")


def check_names(queries) -> None:
    """A non-empty set of registered query names; ConfigError naming ``queries`` otherwise."""
    if not isinstance(queries, frozenset) or not all(isinstance(q, str) for q in queries):
        raise ConfigError("queries", f"must be a set of query names from {', '.join(QUERIES)}")
    unknown = sorted(set(queries) - set(QUERIES))
    if unknown:
        raise ConfigError("queries", f"unknown query {shown(unknown[0])}; choose from {', '.join(QUERIES)}")
    if not queries:
        raise ConfigError("queries", f"ask for at least one of {', '.join(QUERIES)}")


def parse_queries(text: str) -> frozenset[str]:
    """``"fall,direction"`` -> frozenset; raises ConfigError for unknown names (what else a
    QuerySpec needs, such as the contact query's pairs, is checked where the spec is made)."""
    names = frozenset(part.strip() for part in text.split(",") if part.strip())
    check_names(names)
    return names

