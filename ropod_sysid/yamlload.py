"""YAML reading for the platform and parameter files: the safe loader with YAML 1.2 floats.

PyYAML implements YAML 1.1, whose float rule needs a decimal point and a signed exponent, so
``8e-2``, ``1e3`` and ``-.5`` would be read as strings and refused as "not a number". YAML 1.2
(and JSON) read them as floats; so does :func:`safe_load`. Nothing but plain data is ever
constructed (:class:`yaml.SafeLoader`).
"""

from __future__ import annotations

import re
from typing import Any

import yaml

_FLOAT_TAG = "tag:yaml.org,2002:float"
# YAML 1.2 core-schema floats (plus the 1.1 digit separator '_'); plain integers stay integers
_FLOAT = re.compile(r"""^(?:
      [-+]?(?:[0-9][0-9_]*\.[0-9_]*|\.[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)?
    | [-+]?[0-9][0-9_]*[eE][-+]?[0-9]+
    | [-+]?\.(?:inf|Inf|INF)
    | \.(?:nan|NaN|NAN)
    )$""", re.VERBOSE)


class Yaml12SafeLoader(yaml.SafeLoader):
    """:class:`yaml.SafeLoader` whose implicit floats follow YAML 1.2, and which refuses a key
    given twice in one mapping (YAML 1.2 forbids it; PyYAML would keep the last silently)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                continue
            key = self.construct_object(key_node, deep=True)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"the key {key!r} appears twice in one mapping; keep one of them",
                    key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


Yaml12SafeLoader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag != _FLOAT_TAG]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
Yaml12SafeLoader.add_implicit_resolver(_FLOAT_TAG, _FLOAT, list("-+0123456789."))


def safe_load(text: str) -> Any:
    """Parse YAML text to plain data (mappings, lists, str, int, float, bool, None)."""
    return yaml.load(text, Loader=Yaml12SafeLoader)  # noqa: S506 - a SafeLoader subclass
