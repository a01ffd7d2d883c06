"""Strict scalar types for request bodies: JSON `true` is not the number 1, `1.5` is not an
integer (`133.0` is, as JSON Schema reads it), a number is finite (JSON has no NaN or
Infinity; Python's parser accepts them), and text is text every database stores (PostgreSQL
refuses the NUL character, SQLite keeps it)."""

from typing import Annotated, Any

from pydantic import AfterValidator, BeforeValidator, Field, StringConstraints
from pydantic.json_schema import JsonDict
from pydantic_core import PydanticCustomError

MAX_ID = 2**31 - 1
"""The largest id or index a body or path may name: a database's 32-bit int."""
NUL_MESSAGE = "holds the NUL character (\\u0000), which text cannot hold; remove it"
SURROGATE_MESSAGE = (
    "is not valid Unicode (it holds a lone surrogate such as \\ud800); send UTF-8 text"
)


def plain_text(value: str) -> str:
    """Refuse what a database cannot store as text, saying so without repeating the value."""
    if "\x00" in value:
        raise PydanticCustomError("string_nul", "Text " + NUL_MESSAGE)
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise PydanticCustomError("string_unicode", "Text " + SURROGATE_MESSAGE) from None
    return value


def whole_number(value: Any) -> Any:
    """A float without a fraction as the integer it is: JSON Schema's `integer` is any number
    whose fraction is zero (`133.0` is one), and a client generated from the document may
    send it so. `true`, `1.5` and text are left for the strict int to refuse."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


WHOLE = BeforeValidator(whole_number)
Int = Annotated[int, Field(strict=True), WHOLE]
"""An integer field of a body: a JSON integer, or a number without a fraction. Bounds go on
the field (`x: Int = Field(ge=1)`); inside a list or a union, before `WHOLE`
(`Annotated[int, Field(strict=True, ge=1), WHOLE]`): bounds after a validator function reach
the JSON Schema as `ge` and `le`, which it does not know."""
Number = Annotated[float, Field(strict=True, allow_inf_nan=False)]
NO_NUL = r"^[^\x00]*$"
"""JSON Schema's `pattern` for text without the NUL character."""
Text = Annotated[str, AfterValidator(plain_text), Field(json_schema_extra={"pattern": NO_NUL})]
"""A text field of a body (a name, a description, a page text): same 422 on every database."""
Key = Annotated[str, AfterValidator(plain_text), StringConstraints(min_length=1, max_length=64)]
"""A key of a body's map (a config field, a text's name). Its JSON Schema goes in the map's
`propertyNames` (`KEY_NAMES`): a key's own `pattern` would make pydantic write the map's
values under `patternProperties`, leaving any other key's value unchecked."""
KEY_NAMES: JsonDict = {"minLength": 1, "maxLength": 64, "pattern": NO_NUL}
"""The `propertyNames` of a map keyed by `Key`."""
MAX_TEXT = 50_000
"""Characters of one page text (the consent form is the longest, about 3,000)."""
Texts = Annotated[
    dict[Key, Annotated[Text, Field(max_length=MAX_TEXT)]],
    Field(json_schema_extra={"propertyNames": KEY_NAMES}),
]
"""Page texts by key (a study's, or a condition's over them)."""


def _not_blank(value: str) -> str:
    value = value.strip()
    if not value:
        raise PydanticCustomError("blank", "A name must not be blank")
    return value


NAME_PATTERN = (
    r"^[^\x00]*"
    r"[^\x00\t-\r\x1c-\x20\x85\xa0\u1680\u2000-\u200a\u2028\u2029\u202f\u205f\u3000]"
    r"[^\x00]*$"
)
"""JSON Schema's `pattern` for a name: no NUL, and a character `str.strip` keeps (what
Python counts as whitespace spelled out: `\\S` differs between Python's reading and
JSON Schema's)."""
StudyName = Annotated[
    Text,
    StringConstraints(max_length=200),
    AfterValidator(_not_blank),
    Field(json_schema_extra={"pattern": NAME_PATTERN}),
]
"""A study's name: spaces around it dropped, then at least one character."""
