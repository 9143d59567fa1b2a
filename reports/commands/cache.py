"""Show the cache: its folder, budget and size by kind; prune it to the budget, or clear it.

``translucent cache`` lists what the cache holds (references, precomputations, the report's
runs), ``--prune`` removes the least recently used entries until it is within its budget
(``TRANSLUCENT_CACHE_MAX_BYTES``, or ``--max-bytes``), and ``--clear`` removes every entry.
Every store already keeps the cache within its budget; an entry used in the last minute is
never pruned. A removed entry is computed again when it is next needed. Only the cache's own
entries are ever listed or removed; a ``TRANSLUCENT_CACHE`` that is no folder, cannot be
written or is not the cache's (:func:`translucent.cache.check_folder`, the check every write
to the cache passes) is refused with exit 2, as is an entry that cannot be removed.
"""

from __future__ import annotations


def add_arguments(parser):
    """``--prune [--max-bytes N]`` or ``--clear``."""
    action = parser.add_mutually_exclusive_group()
    action.add_argument("--prune", action="store_true",
                        help="remove least recently used entries until the cache is within "
                             "its budget")
    action.add_argument("--clear", action="store_true", help="remove every entry")
    parser.add_argument("--max-bytes", type=int, default=None, metavar="N",
                        help="with --prune: this budget instead of TRANSLUCENT_CACHE_MAX_BYTES "
                             "(0: no limit)")


def _size(nbytes: int) -> str:
    return f"{nbytes / 2**30:.2f} GiB" if nbytes >= 2**30 else f"{nbytes / 2**20:.1f} MiB"


def run(args) -> int:
    """Print the cache's contents; prune or clear it when asked."""
    from collections import Counter

    from ...cache import budget, cache_entries, check_folder, prune
    from ...errors import InputError, check_count
    from .record import record

    if args.max_bytes is not None:
        if not args.prune:
            raise InputError("only with --prune", field="--max-bytes", value=args.max_bytes)
        check_count(args.max_bytes, "--max-bytes", minimum=0)
    limit = budget() if args.max_bytes is None else (args.max_bytes or None)
    folder = check_folder()
    removed = []
    try:
        if args.clear:
            removed = prune(0, folder, keep_recent=False)
        elif args.prune:
            removed = prune(limit, folder)
    except OSError as error:  # an entry in a folder this user may not change
        raise InputError(f"cannot remove the entry {error.filename} "
                         f"({error.strerror or error}); the entries after it are kept",
                         field="TRANSLUCENT_CACHE", value=str(folder)) from None
    entries = cache_entries(folder)
    counts, sizes = Counter(), Counter()
    for entry in entries:
        counts[entry.namespace] += 1
        sizes[entry.namespace] += entry.nbytes
    kinds = {name: (counts[name], sizes[name]) for name in sorted(counts)}
    total = sum(entry.nbytes for entry in entries)
    print(f"cache: {folder}")
    print(f"budget: {_size(limit) if limit else 'no limit'}"
          + ("" if args.max_bytes is not None else " (TRANSLUCENT_CACHE_MAX_BYTES)"))
    for name, (count, nbytes) in kinds.items():
        print(f"  {name}: {count} entr{'y' if count == 1 else 'ies'}, {_size(nbytes)}")
    print(f"total: {len(entries)} entries, {_size(total)}")
    if args.prune or args.clear:
        print(f"removed: {len(removed)} entries, {_size(sum(e.nbytes for e in removed))}")
    record(args, folder=str(folder), budget_bytes=limit, total_bytes=total,
           entries=len(entries),
           kinds={name: {"entries": count, "bytes": nbytes}
                  for name, (count, nbytes) in kinds.items()},
           removed=[{"path": str(e.path), "bytes": e.nbytes} for e in removed])
    return 0
