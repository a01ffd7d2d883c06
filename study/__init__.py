"""The core both processes use: the database, its migrations, the services
as plain functions over domain values, the schemas and the settings."""
