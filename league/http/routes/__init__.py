"""HTTP routers of the league API, one module per resource."""
