"""What the API does, as plain functions on a database session: the routes and the batch
runner (issue 6) both call these, so a session made from Python is a session like any other."""
