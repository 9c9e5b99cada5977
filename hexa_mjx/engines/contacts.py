"""MJX's contact arrays, read in one place.

MJX's JAX implementation keeps the contacts of a step in the private `data._impl.contact`; its Warp
implementation (the GPU path) keeps none there and reports contacts through contact sensors
instead. Everything in hexa_mjx reads MJX contacts through `of` and `normals`, so this module is
the one place a Warp path would plug in.
"""

from __future__ import annotations


def of(data):
    """(geom1, geom2, dist) of every contact slot of an MJX physics state (JAX implementation)."""
    contact = data._impl.contact
    return contact.geom1, contact.geom2, contact.dist


def normals(data):
    """The world-frame normal (n, 3) of every contact slot of an MJX physics state."""
    return data._impl.contact.frame[..., 0, :]
