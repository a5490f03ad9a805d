def main(argv=None):
    print("ncgen")
