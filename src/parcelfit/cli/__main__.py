from parcelfit.cli import main

main()
