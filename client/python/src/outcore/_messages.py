"""Protobuf messages as plain Python values, for the clients' dicts, and the
sum of a call's per-chunk figures.

Thread-safety: pure functions (add_fields writes only its `total`).
"""

from __future__ import annotations


def message_to_dict(message) -> dict:
    """A protobuf message as plain Python values (ints stay ints, unlike
    json_format, which turns uint64 into strings)."""
    out = {}
    for field in message.DESCRIPTOR.fields:
        value = getattr(message, field.name)
        if field.type == field.TYPE_MESSAGE and field.message_type.GetOptions().map_entry:
            value = dict(value)
        elif field.type == field.TYPE_MESSAGE:
            if field.is_repeated:
                value = [message_to_dict(v) for v in value]
            else:
                value = message_to_dict(value)
        elif field.is_repeated:
            value = list(value)
        elif field.enum_type is not None:
            value = field.enum_type.values_by_number[value].name
        out[field.name] = value
    return out


def add_fields(total, part) -> None:
    """Adds every field of `part` to `total`: two messages of one type whose
    fields are all numbers (QueryStats of a call's chunks)."""
    for field in part.DESCRIPTOR.fields:
        setattr(total, field.name, getattr(total, field.name) + getattr(part, field.name))
