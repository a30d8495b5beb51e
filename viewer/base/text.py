"""Text shown to a person: names and values with control characters escaped, on one line."""


def _is_control(c: str) -> bool:
    return ord(c) < 0x20 or 0x7F <= ord(c) < 0xA0 or c in "\u2028\u2029"


def printable(text: str) -> str:
    """`text` with its control characters (a newline, an escape sequence)
    written as escapes, so that it shows on one line as it is."""
    if not any(_is_control(c) for c in text):
        return text
    return "".join(c.encode("unicode_escape").decode("ascii") if _is_control(c) else c for c in text)
