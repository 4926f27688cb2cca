"""The `tamp` command line and what it runs: demo, plan, collection, problem files, runners."""
