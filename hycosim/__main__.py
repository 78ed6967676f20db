from hycosim.cli import app

app(prog_name="hycosim")
