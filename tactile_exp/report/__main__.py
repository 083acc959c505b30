from tactile_exp.report.cli import main

if __name__ == "__main__":
    main()
