"""The bounded YAML loader of ``mavcore.inputs`` (docs/limits.md): PyYAML's safe
loader with an alias budget, a cap on the document's size with its aliases
expanded, and a nesting cap, all counted while composing (nothing is expanded
first). Kept apart so that importing ``mavcore.inputs`` does not import PyYAML:
import this module where a YAML file is read, not at the top of a module.
"""

from __future__ import annotations

import yaml

from .inputs import _DEFAULTS, Limits, brief, clip, limits


def parse_yaml(text: str, source: str, error: type[Exception], lim=None):
    """One YAML document, safely and boundedly loaded, or ``error("<source>: line N", problem)``."""
    return parse_yaml_bounded(text, source, error, lim or limits())


class _TooBig(Exception):
    def __init__(self, message: str, mark=None) -> None:
        super().__init__(message)
        self.mark = mark


class _BoundedComposer(yaml.composer.Composer):
    """PyYAML's composer with an alias budget, an expanded-size cap and a nesting cap."""

    _lim: Limits = _DEFAULTS

    def compose_document(self):
        self._n_aliases = 0
        self._depth = 0
        self._size: dict[int, int] = {}
        return super().compose_document()

    def _over(self, what: str, value: int, name: str, mark) -> None:
        cap = getattr(self._lim, name)
        if value > cap:
            raise _TooBig(f"{what} is {value:,}, above the limit {cap:,} ({Limits.env_name(name)})", mark)

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            self._n_aliases += 1
            self._over("the number of YAML aliases", self._n_aliases, "yaml_aliases", event.start_mark)
            node = super().compose_node(parent, index)
            if id(node) not in self._size:
                raise _TooBig(f"alias *{brief(event.anchor, 30)} refers to a node that contains it (recursive)",
                              event.start_mark)
            return node
        self._depth += 1
        self._over("the YAML nesting depth", self._depth, "nesting_depth", self.peek_event().start_mark)
        node = super().compose_node(parent, index)
        self._depth -= 1
        if isinstance(node, yaml.SequenceNode):
            n = 1 + sum(self._size[id(c)] for c in node.value)
        elif isinstance(node, yaml.MappingNode):
            n = 1 + sum(self._size[id(k)] + self._size[id(v)] for k, v in node.value)
        else:
            n = 1
        self._over("the YAML document with its aliases expanded (nodes)", n, "yaml_nodes", node.start_mark)
        self._size[id(node)] = n
        return node


if getattr(yaml, "__with_libyaml__", False):
    class _Loader(_BoundedComposer, yaml.cyaml.CParser, yaml.constructor.SafeConstructor, yaml.resolver.Resolver):
        """libyaml's parser, the bounded composer, the safe constructor."""

        def __init__(self, stream):
            yaml.cyaml.CParser.__init__(self, stream)
            _BoundedComposer.__init__(self)
            yaml.constructor.SafeConstructor.__init__(self)
            yaml.resolver.Resolver.__init__(self)
else:   # pragma: no cover - PyYAML without libyaml
    class _Loader(yaml.reader.Reader, yaml.scanner.Scanner, yaml.parser.Parser, _BoundedComposer,
                  yaml.constructor.SafeConstructor, yaml.resolver.Resolver):
        def __init__(self, stream):
            yaml.reader.Reader.__init__(self, stream)
            yaml.scanner.Scanner.__init__(self)
            yaml.parser.Parser.__init__(self)
            _BoundedComposer.__init__(self)
            yaml.constructor.SafeConstructor.__init__(self)
            yaml.resolver.Resolver.__init__(self)


def parse_yaml_bounded(text: str, source: str, error: type[Exception], lim: Limits):
    """One YAML document, safely and boundedly loaded, or ``error("<source>: line N", problem)``."""
    loader = _Loader(text)
    loader._lim = lim
    try:
        return loader.get_single_data()
    except _TooBig as exc:
        where = f"{source}: line {exc.mark.line + 1}" if exc.mark is not None else source
        raise error(where, str(exc)) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{source}: line {mark.line + 1}" if mark is not None else source
        problem = getattr(exc, "problem", None) or "parse error"
        raise error(where, f"not valid YAML: {clip(problem)}") from None
    except (ValueError, OverflowError, RecursionError, TypeError) as exc:
        # e.g. an integer of more than sys.get_int_max_str_digits() digits, an unhashable key
        raise error(source, f"not valid YAML: {clip(exc)}") from None
    finally:
        loader.dispose()
