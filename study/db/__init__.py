"""The study database: typed models, the engine, and the Alembic migrations."""
