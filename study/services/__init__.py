"""What the API does, as plain functions on a database session: the routes and the batch
runner (`runs.batch`) both call these, so a session made from Python is a session like any
other."""
