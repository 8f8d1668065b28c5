// Link probe for `make arm`: instantiates the core against do-nothing HAL
// implementations so the linker keeps exactly what the sketch would use, and
// the size of the linked image is measured. Never run.
#include "../core/firmware.h"

namespace {

using namespace chefbot;

volatile uint32_t g_sink;

class ProbeHal : public Clock,
                 public SerialPort,
                 public MotorPins,
                 public EncoderPins,
                 public UltrasonicPins,
                 public ImuSource,
                 public AnalogInput,
                 public ResetLine {
 public:
  uint32_t micros() override { return g_sink; }
  int read_byte() override { return static_cast<int>(g_sink) - 1; }
  size_t tx_space() override { return g_sink; }
  void write(const char* data, size_t len) override { g_sink = static_cast<uint32_t>(data[len - 1]); }
  void apply(Side side, const MotorOutput& out) override { g_sink = side + out.pwm; }
  void begin(EncoderSink& sink) override { sink.encoder_prime(kLeft, g_sink & 1u, g_sink & 2u); }
  void begin(EchoSink& sink) override { sink.echo_edge(true, g_sink); }
  void trigger() override { g_sink = 1; }
  bool poll(Quaternion& q) override {
    q.w = static_cast<float>(g_sink);
    return true;
  }
  uint16_t read_raw() override { return static_cast<uint16_t>(g_sink); }
  void reset_board() override { g_sink = 2; }
};

ProbeHal g_hal;

}  // namespace

// Pure virtual calls cannot happen here; the default handler would pull in
// the C++ runtime's terminate machinery and distort the size.
extern "C" void __cxa_pure_virtual() {
  for (;;) {
  }
}

int main() {
  Hal hal = {&g_hal, &g_hal, &g_hal, &g_hal, &g_hal, &g_hal, &g_hal, &g_hal};
  static Firmware fw(hal, Config());
  fw.begin();
  for (;;) {
    fw.poll();
    fw.encoder_edge(kRight, g_sink & 1u, g_sink & 2u);
  }
}
