from hycosim.cli import main

main()
