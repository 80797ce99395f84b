from wtcli import __version__


def test_version(cli):
    r = cli("--version")
    assert r.exit_code == 0 and r.stdout.strip() == f"wtinspect {__version__}"


def test_unknown_command_is_usage_error(cli):
    assert cli("no-such-command").exit_code == 2
