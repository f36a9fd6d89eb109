// SHA-256 against FIPS 180-4's examples, the CPU's SHA-extension path against
// the portable one, and a file read in chunks against the same bytes whole.
#include <doctest/doctest.h>

#include <cstdio>
#include <fstream>
#include <random>
#include <string>

#include "dn/io/sha256.h"

using namespace dn;

TEST_CASE("sha256: the standard's examples") {
  const std::string million(1000000, 'a');
  const std::pair<std::string, std::string> examples[] = {
      {"", "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"},
      {"abc", "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"},
      {"abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq",
       "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1"},
      {million, "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0"}};
  for (const auto& [bytes, digest] : examples) {
    CHECK(sha256Hex(bytes) == digest);
    CHECK(detail::sha256HexPortable(bytes) == digest);
  }
}

TEST_CASE("sha256: the fast path agrees with the portable one at every tail length") {
  std::mt19937 random(7);
  std::string bytes;
  for (int size = 0; size <= 300; ++size) {
    CHECK(sha256Hex(bytes) == detail::sha256HexPortable(bytes));
    bytes += static_cast<char>(random());
  }
}

TEST_CASE("sha256: a file across the reader's chunk boundary") {
  std::mt19937 random(11);
  std::string bytes((1 << 20) + 4097, '\0');
  for (char& c : bytes) c = static_cast<char>(random());
  const std::string path = "test_sha256_file.bin";
  std::ofstream(path, std::ios::binary) << bytes;
  CHECK(sha256OfFile(path) == detail::sha256HexPortable(bytes));
  std::remove(path.c_str());
  CHECK_THROWS_WITH_AS(sha256OfFile("no/such/file"), "no/such/file: cannot open for reading",
                       std::runtime_error);
}
