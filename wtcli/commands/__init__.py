"""One module per subcommand, each with ``register(app)``; ``wtcli.cli`` discovers them."""
