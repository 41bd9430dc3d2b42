"""Disjoint sets (union-find), for grouping what touches: pixels' neighbours, junction forks,
pieces of cable joined at junctions."""

__all__ = ["DisjointSets"]


class DisjointSets:
    """Disjoint sets over hashable items, with path halving.

    Parameters
    ----------
    items : iterable
        Each starts in a set of its own.
    """

    def __init__(self, items):
        self.parent = {item: item for item in items}
        self.count = len(self.parent)

    def find(self, item):
        """The representative of ``item``'s set."""
        parent = self.parent
        while parent[item] != item:
            parent[item] = parent[parent[item]]
            item = parent[item]
        return item

    def union(self, a, b):
        """Join the sets of ``a`` and ``b``; whether they were apart."""
        a, b = self.find(a), self.find(b)
        if a == b:
            return False
        self.parent[a] = b
        self.count -= 1
        return True

    def groups(self, items=None):
        """Representative -> members (of ``items``, default all), in the items' order."""
        groups = {}
        for item in self.parent if items is None else items:
            groups.setdefault(self.find(item), []).append(item)
        return groups
