// Host driver for examples/arduino/urdaemon_servo_bridge/ssc32_bridge.h: the bridge's pure part on a
// fake I2C bus that prints what the board would have received. tests/examples/test_arduino_bridge.py
// compiles it with g++ (-I the sketch folder, -D the BRIDGE_* settings) and reads its output.
//
// Usage: driver [--absent 0xAA]... < input
//   Every stdin byte is fed to the bridge after bridge.begin(), except driver commands: a line that
//   starts with '@' right after a '\r' (or at the very start) and runs to '\n':
//     @absent 0xAA    from now on, writes to address 0xAA are not acknowledged
//     @present 0xAA   from now on, they are
//   --absent makes an address absent from the start (before begin()).
//
// Output, one event a line, in order (all numbers hex unless said):
//   W 0x40 0x06 00 00 33 01   an acknowledged I2C write: address, then every byte sent (the first is
//                             the register; with MODE1.AI the rest fill it and the registers after)
//   N 0x41 0x00 10            the same for a write nobody acknowledged (the board kept nothing)
//   D 500                     a wait of at least 500 us (decimal)
//   R <text>                  a reply line to the host
//   E                         the driver fed a '\r' (one input line ended)
//   Z dropped=<n>             after the input: lines the bridge dropped (decimal)
// A replay into a register model takes the W lines only: bytes.fromhex of the fields after the
// address (each "0x" removed) is the raw write an smbus2-style bus makes to that address.

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ssc32_bridge.h"

namespace {

class PrintIo : public ssc32_bridge::Io {
 public:
  PrintIo() { memset(absent_, 0, sizeof absent_); }

  bool write(uint8_t address, const uint8_t *bytes, uint8_t length) override {
    const bool acked = !absent_[address & 0x7F];
    printf("%c 0x%02x", acked ? 'W' : 'N', address);
    for (uint8_t i = 0; i < length; ++i) printf(i == 0 ? " 0x%02x" : " %02x", bytes[i]);
    printf("\n");
    return acked;
  }

  void wait_us(uint16_t us) override { printf("D %u\n", static_cast<unsigned>(us)); }

  void reply(const char *line) override { printf("R %s\n", line); }

  void set_absent(uint8_t address, bool absent) { absent_[address & 0x7F] = absent; }

 private:
  bool absent_[128];
};

// "0x41" or "65" → the address; exits on anything else.
uint8_t parse_address(const char *text) {
  char *end = nullptr;
  const long value = strtol(text, &end, 0);
  if (end == text || *end != '\0' || value < 0 || value > 0x7F) {
    fprintf(stderr, "driver: not an I2C address: %s\n", text);
    exit(2);
  }
  return static_cast<uint8_t>(value);
}

// One '@' command line (without the '@' and the '\n').
void run_command(PrintIo &io, const char *command) {
  if (strncmp(command, "absent ", 7) == 0) {
    io.set_absent(parse_address(command + 7), true);
  } else if (strncmp(command, "present ", 8) == 0) {
    io.set_absent(parse_address(command + 8), false);
  } else {
    fprintf(stderr, "driver: unknown command: @%s\n", command);
    exit(2);
  }
}

}  // namespace

int main(int argc, char **argv) {
  PrintIo io;
  for (int i = 1; i < argc; ++i) {
    if (strcmp(argv[i], "--absent") == 0 && i + 1 < argc) {
      io.set_absent(parse_address(argv[++i]), true);
    } else {
      fprintf(stderr, "usage: driver [--absent 0xAA]... < input\n");
      return 2;
    }
  }
  ssc32_bridge::Bridge bridge(io);
  bridge.begin();
  bool line_start = true;
  int c;
  while ((c = getchar()) != EOF) {
    if (line_start && c == '@') {
      char command[64];
      size_t n = 0;
      while ((c = getchar()) != EOF && c != '\n') {
        if (n + 1 < sizeof command) command[n++] = static_cast<char>(c);
      }
      command[n] = '\0';
      run_command(io, command);
      continue;
    }
    bridge.feed(static_cast<char>(c));
    line_start = c == '\r';
    if (line_start) printf("E\n");
  }
  printf("Z dropped=%u\n", static_cast<unsigned>(bridge.dropped()));
  return 0;
}
