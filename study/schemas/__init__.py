"""Request and response bodies of the API, as pydantic families (`XCreate`, `XPublic`)."""
