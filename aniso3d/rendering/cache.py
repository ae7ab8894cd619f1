"""A bounded cache of what is made from an object: conversions (mesh ->
texture -> points, pyramids) and GPU uploads.

Entries are keyed by (source object, key), the key saying how the value was
made (build options, method). The source is held by a weak reference, never
by its ``id()`` alone: when the source is garbage-collected its entries go at
once, so a new object that happens to get the same ``id()`` cannot be handed
the old object's value. (Objects that cannot be weakly referenced are held
strongly until evicted.) A value that refers back to its source (a pyramid
holds its texture as level 0; a pyramid upload holds its pyramid) keeps the
source alive until it is evicted or discarded.

The cache is bounded by a number of entries and by bytes (each value's
``nbytes``), least recently used first out; the newest entry always stays.
An entry that leaves (evicted, discarded, its source collected, or cleared)
is passed to its ``release`` function, e.g. a renderer's ``release(handle)``
that frees GPU objects through the :class:`~aniso3d.rendering.context.GLContext`.
Releases of entries whose source was collected are deferred to the next call
on the cache (a garbage collection may run in the middle of a draw), and
:meth:`Cache.clear` runs any still pending.
"""

from __future__ import annotations

import weakref
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Any

from aniso3d.errors import InputError


@dataclass(eq=False)
class _Entry:
    source: Callable[[], Any]  # weakref.ref, or a strong holder for what cannot be weakly referenced
    value: Any
    nbytes: int
    release: Callable[[Any], None] | None


class _Strong:
    """A strong reference with the call interface of ``weakref.ref``."""

    __slots__ = ("obj",)

    def __init__(self, obj: Any):
        self.obj = obj

    def __call__(self) -> Any:
        return self.obj


class Cache:
    """LRU map (source object, key) -> value, sources held weakly.

    Args:
        max_entries: at most this many entries (>= 1).
        max_bytes: at most this many bytes of values in all (None: no limit);
            a single larger value is still kept, alone.
        name: what the cache holds, for messages.
    """

    def __init__(self, max_entries: int = 32, max_bytes: int | None = None, name: str = "cache"):
        self.name = name
        self.max_entries = max_entries
        self.max_bytes = max_bytes
        self._entries: OrderedDict[tuple[int, Hashable], _Entry] = OrderedDict()
        self._by_source: dict[int, set[Hashable]] = {}
        self._watch: dict[int, weakref.ref] = {}
        self._pending: list[_Entry] = []
        self._check_bounds()

    # ------------------------------------------------------------ queries

    def get(self, source: Any, key: Hashable) -> Any | None:
        """The value made from ``source`` with ``key``, or None; marks it recently used."""
        self._flush()
        k = (id(source), key)
        entry = self._entries.get(k)
        if entry is None:
            return None
        if entry.source() is not source:  # cannot happen while the callbacks run; never trust an id
            self._drop(k)
            return None
        self._entries.move_to_end(k)
        return entry.value

    def __len__(self) -> int:
        return len(self._entries)

    @property
    def nbytes(self) -> int:
        """Bytes of the values held."""
        return sum(e.nbytes for e in self._entries.values())

    def items(self) -> list[tuple[Hashable, Any]]:
        """(key, value) of every entry, least recently used first."""
        return [(key, e.value) for (_, key), e in self._entries.items()]

    # ------------------------------------------------------------ changes

    def put(
        self, source: Any, key: Hashable, value: Any, release: Callable[[Any], None] | None = None,
        nbytes: int | None = None,
    ) -> Any:  # fmt: skip
        """Keep ``value`` as made from ``source`` with ``key`` (replacing, and
        releasing, an earlier one); then evict to the bounds. Returns ``value``.
        ``nbytes`` defaults to the bytes ``value`` holds in memory:
        ``value.memory_nbytes`` where it has one (a texture's ``nbytes`` is its
        compressed, stored size), else ``value.nbytes`` (0 if it has none)."""
        self._flush()
        self._check_bounds()
        sid = id(source)
        k = (sid, key)
        if k in self._entries:
            self._drop(k)
        ref = self._watch.get(sid)
        if ref is None or ref() is not source:
            try:
                ref = weakref.ref(source, self._callback(sid))
            except TypeError:  # not weakly referenceable: held until evicted
                ref = _Strong(source)
            else:
                self._watch[sid] = ref
        size = int(memory_bytes(value) if nbytes is None else nbytes)
        self._entries[k] = _Entry(ref, value, size, release)
        self._by_source.setdefault(sid, set()).add(key)
        self._evict()
        return value

    def get_or_make(
        self, source: Any, key: Hashable, make: Callable[[], Any],
        release: Callable[[Any], None] | None = None,
    ) -> Any:  # fmt: skip
        """The cached value, or ``make()`` kept (see :meth:`put`)."""
        value = self.get(source, key)
        if value is None:
            value = self.put(source, key, make(), release)
        return value

    def discard(self, source: Any) -> list[Any]:
        """Drop (and release) every entry made from ``source``; returns their values."""
        self._flush()
        sid = id(source)
        keys = [k for k in self._by_source.get(sid, ()) if self._entries[(sid, k)].source() is source]
        values = [self._entries[(sid, key)].value for key in keys]
        for key in keys:
            self._drop((sid, key))
        return values

    def collect(self) -> int:
        """Release now the entries whose sources were garbage-collected
        (otherwise released at the next call); returns how many."""
        n = len(self._pending)
        self._flush()
        return n

    def clear(self) -> None:
        """Drop and release every entry (and any release still pending)."""
        while self._entries:
            self._drop(next(iter(self._entries)))
        self._flush()
        self._watch.clear()

    # ------------------------------------------------------------ internals

    def _check_bounds(self) -> None:
        n = self.max_entries
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise InputError(f"{self.name}: max_entries must be a whole number >= 1, got {n!r}")
        b = self.max_bytes
        if b is not None and (isinstance(b, bool) or not isinstance(b, int) or b < 0):
            raise InputError(f"{self.name}: max_bytes must be a whole number >= 0 or None, got {b!r}")

    def _evict(self) -> None:
        while len(self._entries) > 1 and (
            len(self._entries) > self.max_entries
            or (self.max_bytes is not None and self.nbytes > self.max_bytes)
        ):
            self._drop(next(iter(self._entries)))

    def _drop(self, k: tuple[int, Hashable]) -> None:
        """Remove one entry and release it now."""
        entry = self._unlink(k)
        if entry is not None and entry.release is not None:
            entry.release(entry.value)

    def _unlink(self, k: tuple[int, Hashable]) -> _Entry | None:
        entry = self._entries.pop(k, None)
        sid, key = k
        keys = self._by_source.get(sid)
        if keys is not None:
            keys.discard(key)
            if not keys:
                del self._by_source[sid]
                self._watch.pop(sid, None)
        return entry

    def _callback(self, sid: int) -> Callable[[weakref.ref], None]:
        this = weakref.ref(self)

        def gone(ref: weakref.ref) -> None:
            # Runs when the source dies, before its id can be reused: unlink
            # its entries now, release them at the next call on the cache.
            cache = this()
            if cache is None or cache._watch.get(sid) is not ref:
                return
            for key in list(cache._by_source.get(sid, ())):
                entry = cache._unlink((sid, key))
                if entry is not None:
                    cache._pending.append(entry)
            cache._watch.pop(sid, None)

        return gone

    def _flush(self) -> None:
        while self._pending:
            entry = self._pending.pop()
            if entry.release is not None:
                entry.release(entry.value)


def memory_bytes(value: Any) -> int:
    """Bytes ``value`` holds in memory: ``memory_nbytes`` where it has one,
    else ``nbytes``, else 0."""
    if hasattr(value, "memory_nbytes"):
        return int(value.memory_nbytes)
    return int(getattr(value, "nbytes", 0))
