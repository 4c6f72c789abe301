// Arbitrary serial baud rates (e.g. the VersaVIS's 250000) through termios2 /
// BOTHER. Kept apart: <asm/termbits.h> cannot share a file with <termios.h>.
#include <asm/termbits.h>
#include <sys/ioctl.h>

namespace sl::drivers::serial_detail {

bool setCustomBaud(int fd, int baud) {
  struct termios2 tio;
  if (ioctl(fd, TCGETS2, &tio) != 0) return false;
  tio.c_cflag &= ~static_cast<tcflag_t>(CBAUD);
  tio.c_cflag |= BOTHER;
  tio.c_ispeed = static_cast<speed_t>(baud);
  tio.c_ospeed = static_cast<speed_t>(baud);
  return ioctl(fd, TCSETS2, &tio) == 0;
}

}  // namespace sl::drivers::serial_detail
