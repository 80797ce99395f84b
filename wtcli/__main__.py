from wtcli.cli import main

main()
